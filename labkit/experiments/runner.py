"""The one runner: executes a plan's steps on a rig, writes the run file, and shuts down safely.

Guarantees
----------
* Every output that drives the PZT or the shaker is off when :meth:`Runner.run`
  returns or raises, whatever the reason: normal end, exception, Ctrl-C
  (KeyboardInterrupt), SIGTERM (:class:`labkit.errors.Interrupted`), an
  interlock, or a lost instrument (the generator is reconnected to send the
  OFF when its own link was lost). The shutdown runs with SIGINT/SIGTERM held.
* Each point is written and flushed before the next begins; a point's rows
  are written with signals held, so an interrupt never leaves them half
  written.
* Interlocks (vibrometer over-range, tray displacement above its limit, the
  shaker envelope) stop the point, turn the drive off, record why (``/points``
  status ``interlock`` and ``/events``), then skip to the next point or end
  the run (``run.on_interlock``).
* The drive is turned off before the laser spot is moved to another in-chip
  location (the person may touch the setup); within a shaker point the tray and
  robot measurements are taken with the drive on (the robot keeps its state).
* A lower amplitude is programmed before a new frequency, never after, so no
  intermediate generator state drives the shaker harder than either point.
* Reaching a tray displacement: start small (``tray_control.start_vpp``, or
  the response per volt measured at the previous amplitude of the same
  frequency), then scale the drive by request/measured, at most
  ``max_step_ratio`` per step, until within ``tolerance``; every measured
  amplitude is checked against ``interlock.tray_max_um`` and the envelope,
  and every drive against the amplifier's input cap, before it is sent.
"""
from __future__ import annotations

import contextlib
import logging
import math
import os
import sys
import time
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypedDict, cast

import numpy as np

from labkit.errors import DriveNotOff, InputError, InstrumentError, Interrupted, LimitError
from labkit.experiments import kinds, live, measure
from labkit.experiments.config import ShakerConfig
from labkit.experiments.kinds import POINT_OVERHEAD_BYTES, Config
from labkit.experiments.plans import ChirpPoint, MoveSpot, Plan, ShakerPoint, SinePoint
from labkit.experiments.rig import Rig
from labkit.experiments.runfile import Row, RunFile, WriteFailed
from labkit.experiments.safety import (
    RECONNECT_WINDOW_S,
    DriveGuard,
    Interlock,
    check_stop,
    deferred,
    mark_completed,
    shielded,
    signals_raise,
    stop_handled,
)
from labkit.progress import progress

#: the run's shutdown path (``labkit -v`` shows it on stderr)
_log = logging.getLogger(__name__)

#: how long past twice the record an acquisition may take before the scope counts as lost
#: (a missing trigger; generous because a simulated robot may be computed meanwhile)
ACQUIRE_MARGIN_S = 10.0
#: cycles a point's burst runs beyond settle + dwell (the scope's record must end inside it)
BURST_MARGIN_CYCLES = 2
#: a point whose measured drive differs from the commanded one by more than this (relative) is
#: flagged: the generator was changed or switched off outside the run, or its cable came loose
DRIVE_TOLERANCE = 0.2


#: points whose timing a runner keeps (the bench reads them; a long run keeps no more)
TIMING_POINTS = 256
#: dropped links a run replaces (each within safety.RECONNECT_WINDOW_S) before a drop ends it
MAX_RECONNECTS = 3
#: an idle level within this of 0 V counts as no DC on the load, V
IDLE_TOLERANCE_V = 1e-6


def burst_idle(amp_vpp: float, offset_v: float) -> tuple[float, float]:
    """The burst start phase (deg) whose level is nearest 0 V, and that level (V).

    A sine burst of whole cycles ends at its start phase and the output holds that level
    until the next burst: ``offset_v + amp_vpp/2 * sin(phase)``. With ``|offset_v| <= amp_vpp/2``
    (the in-chip drive's 2 V offset under 4 Vpp) it is 0 V; otherwise the nearest the sine comes.
    """
    half = amp_vpp / 2
    if not half > 0:
        return 0.0, offset_v
    s = max(-1.0, min(1.0, -offset_v / half))
    return math.degrees(math.asin(s)), offset_v + half * s


@dataclass
class Programmed:
    """What the runner has programmed on the instruments, so a point sends only what changed.

    After a reconnect nothing is assumed: the runner starts a fresh one.
    """

    sine_set: tuple[float, float] | None = None     # (amp_vpp, offset_v) on the generator
    freq_set: float | None = None                   # its frequency, Hz
    record_s: float | None = None                   # the scope's record length, s
    record_delay: tuple[float, float] | None = None  # (record_s, delay_s) set on the scope
    burst_n: int | None = None                      # cycles of the armed burst
    burst_phase: float | None = None                # its start phase, deg (sets the level between bursts)
    burst_end: float = 0.0                          # time.monotonic() when the last burst ends by itself


class InterlockRecord(TypedDict):
    """A point an interlock stopped (the session's JSON summary lists them)."""

    index: int
    reason: str


class InterlockEnd(LimitError):
    """The run ended on an interlock (``on_interlock = "end"``); the file is complete up to it."""


class Runner:
    """Executes plans on a :class:`labkit.experiments.rig.Rig`, writing a :class:`RunFile`.

    Parameters
    ----------
    rig:
        Open instruments and the spot mover.
    runfile:
        The run file being written (new or resumed).
    cfg:
        The validated config (InchipConfig or ShakerConfig).
    quiet:
        No progress bar.
    """

    def __init__(self, rig: Rig, runfile: RunFile, cfg: Config, *, quiet: bool = False) -> None:
        self.rig = rig
        self.file = runfile
        self.cfg = cfg
        self.quiet = quiet
        self.guard: DriveGuard = rig.guard      # the generator's one owner
        self.guard.log = self._event
        self.point_bytes = kinds.of(cfg).point_bytes(cfg)
        self.spot: str | None = None
        self.prog = Programmed()                 # what is programmed now (sent again only when it changes)
        self.interlocks: list[InterlockRecord] = []
        self.gain_um_per_vpp: dict[float, float] = {}       # shaker: tray response per drive volt
        # per point: total, waited (for the bench); the last TIMING_POINTS only (flat memory)
        self.timing: deque[dict[str, float]] = deque(maxlen=TIMING_POINTS)
        # bounded drive: each acquisition is a finite burst (settle + dwell cycles), armed per point
        self.bounded = False
        self.reconnects = 0                      # dropped links replaced so far (at most MAX_RECONNECTS)
        self.drive_set_vpp: float | None = None  # amplitude commanded (for the measured-drive check)
        self.live = live.LiveStream(runfile.path, live.console_for_run(quiet))   # RUN.live.jsonl
        self.last_rec: tuple[measure.Records, float | None, float | None] | None = None  # + V/div then

    # -- events ------------------------------------------------------------------------------
    def _event(self, text: str) -> None:
        try:
            self.file.event(text)
        except Exception as exc:  # the log must never stop a shutdown
            _log.info("event not written to the run file (%s: %s): %s", type(exc).__name__, exc, text)
        self.live.event(text)

    def _live_point(self, p: Any, rows: Row, loc: Row | None) -> None:
        """The finished point into the live stream, with its last record's levels on the scope."""
        from labkit.experiments.rig import VERTICAL_DIVS

        scope = None
        if self.last_rec is not None and rows.get("status") == "ok":
            rec, dvpd, vvpd = self.last_rec
            scope = live.record_levels(rec.drive_v, rec.velocity_v, dvpd and dvpd * VERTICAL_DIVS / 2,
                                       vvpd and vvpd * VERTICAL_DIVS / 2)
        self.last_rec = None
        try:            # the live view must never stop a run
            self.live.point(p.index, rows, loc, scope, drive_set_vpp=self.drive_set_vpp,
                            over_range="over-range" in str(rows.get("reason", "")))
        except Exception as exc:
            self._event(f"live stream: point {p.index} not written ({type(exc).__name__}: {exc})")

    def _check_stop_request(self) -> None:
        """A Stop "after this point" from ``labkit view``: the same way out as a signal."""
        why = self.live.stop_requested()
        if why is not None:
            self._event(f"stop requested: {why}")
            raise Interrupted("STOP (labkit view)")

    # -- the run -----------------------------------------------------------------------------
    def run(self, plan: Plan) -> str:
        """Execute ``plan``; return the final status (``"complete"``).

        Raises whatever stopped the run (KeyboardInterrupt, Interrupted,
        InstrumentError, InterlockEnd, ...) after the drive is off and the file
        is finished.
        """
        status = "aborted: unexpected error"
        mark_completed(None)
        n_done = plan.points_total - len(plan.points)
        try:
            with signals_raise(), progress(None, f"{plan.kind}", quiet=self.quiet) as bar:
                bar.total = plan.est_s
                bar.bar_format = "{desc} {percentage:3.0f}%|{bar}| {postfix} [{elapsed}<{remaining}]"
                bar.set_postfix_str(f"point {n_done}/{plan.points_total}", refresh=False)
                self.live.start(kind=self.file.kind, points_planned=plan.points_total, points_done=n_done,
                                est_s=plan.est_s, locations=list(getattr(self.cfg, "locations", ()) or ()),
                                config=str(getattr(self.cfg, "path", "") or ""))
                self._event(f"run started: {len(plan.points)} of {plan.points_total} points to measure")
                self._declare_bounded(plan)
                m = self.cfg.method
                if m.kind == "stepped":
                    self.rig.set_record_points(math.ceil(m.dwell_cycles * self.cfg.scope.samples_per_cycle))
                for step in plan.steps:
                    check_stop()        # a stop signal whose exception was dropped (safety._PENDING)
                    self._check_stop_request()
                    if isinstance(step, MoveSpot):
                        self._move_spot(step.spot, drive_off=True)
                        continue
                    t0 = time.monotonic()
                    self._point_reconnecting(step)
                    n_done += 1
                    bar.set_postfix_str(f"point {n_done}/{plan.points_total}", refresh=False)
                    bar.update(step.est_s)
                    self.timing[-1]["total_s"] = time.monotonic() - t0
                self._wait_burst_end()      # a normal end lets the last burst end by itself
                check_stop()
            status = "complete"
        except InterlockEnd as exc:
            status = f"aborted: interlock: {exc.message}"
            raise
        except KeyboardInterrupt:
            stop_handled()
            status = "interrupted: SIGINT"
            raise
        except Interrupted as exc:
            stop_handled()
            status = f"interrupted: {exc.signame}"
            raise
        except BaseException as exc:
            status = f"aborted: {type(exc).__name__}: {exc}"
            raise
        finally:
            finish_error = self._shutdown(status)
        if finish_error is not None:
            # the drive is off and every point is on disk, but the file does not say how the
            # run ended: do not report "complete"
            raise InputError(f"could not write the run's final status ({finish_error})",
                             file=self.file.path) from finish_error
        return status

    def _shutdown(self, status: str) -> Exception | None:
        """Drive off, then the final status into the file; returns the file's error, if any."""
        finish_error: Exception | None = None
        drive_error: DriveNotOff | None = None
        ending = sys.exc_info()[1]          # what ended the run (None: it completed)
        _log.info("shutdown: %s", status)
        with shielded() as arrived:
            try:
                self.guard.final_off(status)
            except DriveNotOff as exc:     # reported after the file says so (exit 4, with a banner)
                drive_error = exc
                status = f"{status}; DRIVE OFF NOT CONFIRMED"
            if arrived:
                _log.info("shutdown: signal(s) %s held until the drive was off", arrived)
                self._event(f"signal(s) {arrived} arrived during shutdown")
            self._event(f"run ended: {status}")
            try:
                self.file.finish(status)
                if status == "complete":
                    mark_completed(str(self.file.path))
            except Exception as exc:   # another error may be in flight: never mask it
                finish_error = exc
                _log.warning("shutdown: the final status could not be written: %s", exc)
            self.live.end(status, drive_error or ending or finish_error)
            _log.info("shutdown: run file and live stream finished (%s)", self.file.path)
        if drive_error is not None:
            raise drive_error
        return finish_error

    # -- bounded drive -----------------------------------------------------------------------
    def _declare_bounded(self, plan: Plan) -> None:
        """Decide whether each point's drive is a finite burst; say so (console, events, file)."""
        fg, scope = self.guard.funcgen, self.rig.scope
        if self.cfg.method.kind == "chirp":
            why = ("a chirp is a generator sweep, which keeps running between triggers: if this "
                   "computer dies mid-run, the drive stays on until someone turns it off")
        elif not scope.record_delay:            # every generator bursts (FunctionGenerator.burst)
            why = f"the {scope.model} driver cannot delay its record past the settling"
        else:
            why = ""
        self.bounded = not why
        if self.bounded:
            text = ("drive bounded: each acquisition is a burst of settle + dwell cycles "
                    f"(+{BURST_MARGIN_CYCLES}); the generator stops by itself at its end")
            offset = float(getattr(self.cfg, "offset_v", 0.0) or 0.0)
            amp = float(getattr(self.cfg, "amp_vpp", 0.0) or 0.0)
            phase, idle = burst_idle(amp, offset)
            text += f"; between bursts the output idles at {idle:.3g} V (burst start phase {phase:g} deg)"
            if abs(idle) > IDLE_TOLERANCE_V:
                _warn(f"between bursts the generator holds {idle:.3g} V DC on the PZT (|offset_v| {abs(offset):g} V "
                      f"> amp_vpp/2 = {amp / 2:g} V: no start phase reaches 0 V); if this computer dies mid-run "
                      f"that DC stays until someone runs 'labkit off {self.cfg.path}' or presses the generator's "
                      "Output key (docs/faults.md)")
        else:
            text = f"DRIVE NOT BOUNDED: {why}"
            fg.burst_off()            # a bounded run before may have left burst mode on
            _warn(text)
        self._event(text)
        try:
            self.file.set_attrs(drive_bounded=self.bounded, drive_bounded_note=text)
        except Exception as exc:   # the events say it too
            _log.info("drive_bounded not written to the run file: %s: %s", type(exc).__name__, exc)

    def _arm_burst(self, freq_hz: float, settle_s: float, hold_s: float) -> None:
        """Burst mode with enough cycles for ``settle_s + hold_s`` at ``freq_hz`` (re-armed when it changes)."""
        if not self.bounded:
            return
        n = math.ceil((settle_s + hold_s) * freq_hz) + BURST_MARGIN_CYCLES
        phase = burst_idle(*(self.prog.sine_set or (0.0, 0.0)))[0]
        if (n, phase) != (self.prog.burst_n, self.prog.burst_phase):
            self._wait_burst_end()          # never re-arm a running burst
            self.guard.funcgen.burst(n, trigger_source="BUS", start_phase_deg=phase)
            self.prog.burst_n, self.prog.burst_phase = n, phase

    def _wait_burst_end(self) -> None:
        """A trigger during a running burst is ignored by the generator: wait for its end."""
        left = self.prog.burst_end - time.monotonic()
        if left > 0:
            time.sleep(left)

    def _fire_burst(self, freq_hz: float) -> float:
        """Start the armed burst (``*TRG``) once the last one has ended; return the start (monotonic)."""
        assert self.prog.burst_n is not None
        self._wait_burst_end()
        t = time.monotonic()
        self.guard.funcgen.trigger()
        # the burst starts when the generator reads *TRG, somewhere between t and the trigger's
        # return (after it, when the driver reads the error queue on the same link): count its
        # end from the return. From t, a trigger that took over 2 ms to arrive (a loaded machine)
        # let the next point's commands cut the burst short (seen once on the virtual lab: 86 us)
        self.prog.burst_end = time.monotonic() + self.prog.burst_n / freq_hz + 0.002
        return t

    def _no_drive_in(self, rec: measure.Records) -> bool:
        want = self.drive_set_vpp
        if not want:
            return False
        vpp = 2 * math.sqrt(2) * float(np.std(rec.drive_v))     # a sine's Vpp from its rms
        return bool(vpp < (1 - DRIVE_TOLERANCE) * want)

    def _check_predicted(self, freq_hz: float, x_um: float, vpp: float) -> None:
        """Interlock (nothing sent) when ``vpp`` is predicted to move the tray ``x_um``, past a limit."""
        cfg = cast(ShakerConfig, self.cfg)
        if x_um > cfg.tray_max_um:
            raise Interlock(f"{vpp:.4g} Vpp would move the tray about {x_um:.3g} um (from the response "
                            f"measured at a lower drive), above interlock.tray_max_um = {cfg.tray_max_um:g} um;"
                            " not sent")
        try:
            self.rig.check_envelope(freq_hz, x_um)
        except Interlock as il:
            raise Interlock(f"{il.reason} (predicted for {vpp:.4g} Vpp from the tray's response "
                            "at a lower drive)") from None

    def _check_measured_drive(self, ph: measure.SinePhasors) -> None:
        """Interlock when the drive the scope saw is not the one commanded (off, changed, unplugged)."""
        want = self.drive_set_vpp
        if want is None or not want > 0:
            return
        got = 2 * abs(ph.drive_v)
        if not abs(got / want - 1) <= DRIVE_TOLERANCE:
            raise Interlock(f"drive measured {got:.4g} Vpp, commanded {want:.4g} Vpp (more than "
                            f"{DRIVE_TOLERANCE:.0%} off): the generator was switched off or changed "
                            "outside this run, or its cable is loose")

    def _no_trigger(self) -> None:
        """After an acquisition that never triggered (the scope waits in NORMal sweep): an output found
        off explains it (no drive, no sync) and is an interlock on this point, not a fault of the rig."""
        if self.guard.is_on and not self.guard.funcgen.output_on:
            raise Interlock(f"no trigger: drive measured off by the generator (its output query), commanded "
                            f"{self.drive_set_vpp or 0:.4g} Vpp: the generator was switched off outside this run")

    # -- steps -------------------------------------------------------------------------------
    def _move_spot(self, spot: str, *, drive_off: bool) -> None:
        if spot == self.spot:
            return
        if drive_off:
            self.guard.off(f"moving the laser to {spot}")
        self.rig.move_spot(spot)
        self.spot = spot
        self._event(f"laser spot at {spot}")

    def _point(self, p: Any) -> None:
        t_start = time.time()
        # room for the point before driving it (DiskFull stops the run cleanly: drive off, status written)
        self.file.ensure_room(self.point_bytes)
        try:
            rows, loc_rows, records = _MEASURE[type(p)](self, p)
            rows.update(status="ok")
        except Interlock as il:
            self.guard.off(f"interlock: {il.reason}")
            self._event(f"interlock at point {p.index}: {il.reason}")
            self.interlocks.append({"index": p.index, "reason": il.reason})
            rows = self._empty_row(p)
            rows.update(status="interlock", reason=il.reason)
            with deferred(), self._writing(p.index):
                self.file.end_point(p.index, rows | {"time_unix_s": time.time(),
                                                    "duration_s": time.time() - t_start})
            self._live_point(p, rows, None)
            if self.cfg.on_interlock == "end":
                raise InterlockEnd(f"{il.reason} at point {p.index}; run ended (run.on_interlock = 'end')",
                                   limit="interlock") from None
            self.timing.append({"waited_s": 0.0})
            return
        self.file.ensure_room(_nbytes(loc_rows, records) + POINT_OVERHEAD_BYTES)
        with deferred(), self._writing(p.index):      # all of a point's rows, or none
            if loc_rows is not None:
                self.file.add_location_rows(str(loc_rows.pop("location")), loc_rows)
            if records is not None:
                group, dt, arrays = records
                self.file.add_records(group, p.index, dt, arrays)
            self.file.end_point(p.index, rows | {"time_unix_s": time.time(), "duration_s": time.time() - t_start})
        self._live_point(p, rows, loc_rows)

    def _point_reconnecting(self, p: Any) -> None:
        """:meth:`_point`; a link dropped during it is replaced within the reconnect window and the
        point measured again from the start (none of its rows were written: nothing is lost
        or doubled). Past :data:`MAX_RECONNECTS` per run, or when the link does not come back
        in time, the error ends the run as before (drive off, exit 3; 4 if OFF is unconfirmed)."""
        while True:
            try:
                self._point(p)
                return
            except DriveNotOff:
                raise
            except InstrumentError as exc:
                role = self._dropped_role(exc)
                if role is None or self.reconnects >= MAX_RECONNECTS:
                    raise
                self.reconnects += 1
                self._event(f"point {p.index}: the {role}'s link dropped ({exc}); reconnecting "
                            f"(window {RECONNECT_WINDOW_S:g} s)")
                try:
                    if role != "funcgen":
                        self.guard.off(f"the {role}'s link dropped")
                    self.rig.reconnect(role, RECONNECT_WINDOW_S)
                except InstrumentError as again:
                    self._event(f"the {role} did not come back: {again}")
                    raise exc from again
                self._forget_settings()
                self._event(f"the {role} is back (same *IDN?); point {p.index} measured again")

    def _dropped_role(self, exc: InstrumentError) -> str | None:
        """The role (funcgen, scope) whose link the peer closed, if ``exc`` came from one; else None."""
        for role, inst in (("funcgen", self.guard.funcgen), ("scope", self.rig.scope)):
            if exc.instrument != getattr(inst, "name", None):
                continue
            dropped = getattr(getattr(inst, "transport", None), "dropped", None)
            return role if dropped is not None and dropped() else None
        return None

    def _forget_settings(self) -> None:
        """After a reconnect nothing programmed is assumed: the next point sends it all again."""
        self.prog = Programmed()
        m = self.cfg.method
        if m.kind == "stepped":
            self.rig.set_record_points(math.ceil(m.dwell_cycles * self.cfg.scope.samples_per_cycle))

    @contextlib.contextmanager
    def _writing(self, index: int) -> Iterator[None]:
        """A failed write (disk, file system, HDF5) becomes WriteFailed; run() turns the drive off first."""
        try:
            yield
        except (OSError, RuntimeError, ValueError) as exc:
            raise WriteFailed(f"writing point {index} failed ({type(exc).__name__}: {exc}); the drive was "
                              "turned off; the file holds every point completed before it; fix the disk, "
                              "then continue with --resume", file=self.file.path, key="--out") from exc

    def _empty_row(self, p: Any) -> Row:
        row: Row = {"location": getattr(p, "location", getattr(p, "robot_spot", "")),
                    "freq_hz": getattr(p, "freq_hz", float("nan")), "reason": ""}
        if isinstance(p, ShakerPoint):
            nan = float("nan")
            row.update(tray_amp_request_um=p.tray_amp_um if p.tray_amp_um is not None else nan,
                       drive_request_vpp=p.drive_vpp if p.drive_vpp is not None else nan, drive_vpp=nan,
                       iterations=0, tray_amp_um=nan, tray_velocity_mm_s=complex(nan, nan),
                       robot_velocity_mm_s=complex(nan, nan), transmissibility=complex(nan, nan),
                       quality=0.0, video="", video_frames=0)
        return row

    # -- stepped sine ------------------------------------------------------------------------
    def _set_sine(self, freq_hz: float, amp_vpp: float, offset_v: float) -> None:
        """Program the generator, sending only what changed (fewer round trips per point).

        A bounded run's last burst is left to end by itself first: the scope's record ends
        inside it (BURST_MARGIN_CYCLES), so the next point would otherwise reprogram a
        running burst."""
        self._wait_burst_end()
        fg = self.guard.funcgen
        if self.prog.sine_set is not None and self.prog.sine_set[1] == offset_v and amp_vpp < self.prog.sine_set[0]:
            # Lower the amplitude BEFORE moving the frequency: the old, larger drive must never
            # meet a frequency where it would move the shaker further (x ~ V / f^2).
            fg.set_amplitude(amp_vpp)
            if self.prog.freq_set != freq_hz:
                fg.set_frequency(freq_hz)
            self.prog.sine_set = (amp_vpp, offset_v)
            self.rig.on_drive_amplitude(amp_vpp, offset_v)
        elif self.prog.sine_set != (amp_vpp, offset_v):
            fg.set_sine(freq_hz, amp_vpp, offset_v)
            self.prog.sine_set = (amp_vpp, offset_v)
            self.rig.on_drive_amplitude(amp_vpp, offset_v)
        elif self.prog.freq_set != freq_hz:
            fg.set_frequency(freq_hz)
        self.prog.freq_set = freq_hz
        self.drive_set_vpp = amp_vpp

    def _settle_and_acquire(self, freq_hz: float, settle_s: float, dwell_s: float,
                            t_changed: float) -> tuple[measure.Records, float]:
        """Wait out the settling (from ``t_changed``), record ``dwell_s``; interlock on over-range.

        Returns the record and the time spent waiting for the physics (settle + dwell), s.
        """
        rig = self.rig
        if self.prog.record_s != dwell_s:
            rig.scope.set_timebase(dwell_s)
            self.prog.record_s = dwell_s
            self.prog.record_delay = None
        if self.bounded:
            # each acquisition is its own burst: the response starts from rest at the trigger
            if self.prog.record_delay != (dwell_s, settle_s):
                rig.scope.set_record_delay(dwell_s, settle_s)
                self.prog.record_delay = (dwell_s, settle_s)
            waited = 0.0
        else:
            left = settle_s - (time.monotonic() - t_changed)
            if left > 0:
                time.sleep(left)
            waited = max(left, 0.0)
        retries = 2      # the scope may miss a burst's start on a loaded machine
        n_avg = self.cfg.scope.averages      # records the scope averages into one (scope.acquisition)
        for _attempt in range(6):
            t_acq = time.monotonic()
            if self.bounded:
                self._wait_burst_end()       # before arming: the trigger must follow the arm at once
                try:
                    rec = measure.acquire_burst(rig.scope, lambda: self._fire_burst(freq_hz),
                                                rig.drive_channel, rig.velocity_channel, settle_s, dwell_s,
                                                timeout_s=(settle_s + dwell_s) * 2 * n_avg + ACQUIRE_MARGIN_S,
                                                averages=n_avg)
                except InstrumentError as exc:
                    if not getattr(exc, "no_trigger", False):
                        raise
                    self._no_trigger()
                    if not retries:
                        raise
                    retries -= 1    # NORMal sweep: a missed burst start is a timeout, not a silent record
                    self._event(f"no trigger at {freq_hz:g} Hz (the burst's start missed?): acquiring once more")
                    continue
                waited += min(settle_s + dwell_s, time.monotonic() - t_acq)
                if retries and self._no_drive_in(rec):
                    # the scope may have missed the burst's start (it then records silence): once more;
                    # a drive that is really off is flagged by the caller's measured-drive check
                    retries -= 1
                    self._event(f"too little drive in the record at {freq_hz:g} Hz: acquiring once more")
                    continue
            else:
                try:
                    rec = measure.acquire(rig.scope, (rig.drive_channel, rig.velocity_channel), dwell_s,
                                          timeout_s=dwell_s * 2 * n_avg + ACQUIRE_MARGIN_S, averages=n_avg)
                except InstrumentError as exc:
                    if getattr(exc, "no_trigger", False):
                        self._no_trigger()
                    raise
                waited += min(dwell_s, time.monotonic() - t_acq)
            self.last_rec = (rec, getattr(rig, "drive_vpd", None), getattr(rig, "velocity_vpd", None))
            if rig.vibrometer.over_range():
                raise Interlock("vibrometer over-range")
            if not rig.velocity_clipped(rec.velocity_v) or not rig.widen_velocity_range():
                break
        return rec, waited

    def _sine_point(self, p: SinePoint) -> tuple[Row, Row | None, Any]:
        self._set_sine(p.freq_hz, p.amp_vpp, p.offset_v)
        self._arm_burst(p.freq_hz, p.settle_s, p.dwell_s)     # before the output goes on
        t_changed = time.monotonic()
        self.guard.on()
        rec, waited = self._settle_and_acquire(p.freq_hz, p.settle_s, p.dwell_s, t_changed)
        ph = measure.sine_phasors(rec, p.freq_hz, self.rig.scale_mm_s_per_v, self.rig.velocity_delay_s)
        self._check_measured_drive(ph)
        self.timing.append({"waited_s": waited, "settle_s": p.settle_s, "dwell_s": p.dwell_s})
        rows: Row = {"location": p.location, "freq_hz": p.freq_hz, "reason": ""}
        loc: Row = {"location": p.location, "freq_hz": p.freq_hz, "frf": ph.frf, "quality": ph.quality,
                    "drive_v": ph.drive_v, "velocity_mm_s": ph.velocity_mm_s, "point_index": p.index}
        records = None
        if self.cfg.method.keep_raw:
            records = ("raw", rec.dt_s, {"drive_v": (rec.drive_v, "V"), "velocity_v": (rec.velocity_v, "V")})
        return rows, loc, records

    # -- chirp -------------------------------------------------------------------------------
    def _chirp_point(self, p: ChirpPoint) -> tuple[Row, Row | None, Any]:
        rig = self.rig
        fg = self.guard.funcgen
        fg.set_sine(p.start_hz, p.amp_vpp, p.offset_v)
        rig.on_drive_amplitude(p.amp_vpp, p.offset_v)
        self.prog.sine_set = None
        fg.set_sweep(p.start_hz, p.stop_hz, p.length_s, spacing=p.spacing, trigger_source="BUS")
        self.guard.on()
        rig.chirp_timebase(p.length_s)
        rig.set_record_points(math.ceil(p.length_s * p.stop_hz * 10))
        self.prog.record_s = p.length_s
        self.prog.record_delay = None
        records = []
        try:
            for _ in range(p.averages):
                measure.arm(rig.scope)     # armed before the sweep starts: in NORMal sweep a start
                fg.trigger()               # the scope missed would be a timeout
                rig.scope.wait_done(p.length_s * 2 + ACQUIRE_MARGIN_S)
                wd = rig.scope.read_waveform(rig.drive_channel)
                wv = rig.scope.read_waveform(rig.velocity_channel)
                if rig.vibrometer.over_range():
                    raise Interlock("vibrometer over-range")
                records.append(measure.Records(np.asarray(wd.volts, float), np.asarray(wv.volts, float),
                                               float(wd.xinc_s)))
        finally:
            try:
                fg.sweep_off()
            except InstrumentError:
                pass
        f, h, coh = measure.chirp_h1(records, rig.scale_mm_s_per_v, p.start_hz, p.stop_hz,
                                     rig.velocity_delay_s)
        self.timing.append({"waited_s": p.averages * p.length_s})
        rows: Row = {"location": p.location, "freq_hz": float("nan"), "reason": ""}
        loc: Row = {"location": p.location, "freq_hz": f, "frf": h, "quality": coh, "coherence": coh,
                    "point_index": np.full(f.shape, p.index)}
        raw = None
        if self.cfg.method.keep_raw:
            raw = ("raw", records[0].dt_s, {
                "drive_v": (np.concatenate([r.drive_v for r in records]), "V"),
                "velocity_v": (np.concatenate([r.velocity_v for r in records]), "V")})
        return rows, loc, raw

    # -- shaker ------------------------------------------------------------------------------
    def _shaker_point(self, p: ShakerPoint) -> tuple[Row, Row | None, Any]:
        cfg, rig = cast(ShakerConfig, self.cfg), self.rig     # shaker points come from shaker plans
        f = p.freq_hz
        self._move_spot("tray", drive_off=False)
        waited = 0.0
        target_vpp = float(p.drive_vpp or 0.0)   # a shaker point has a tray amplitude or a drive
        gain = self.gain_um_per_vpp.get(f)
        if p.tray_amp_um is not None:
            rig.check_envelope(f, p.tray_amp_um)          # LimitError -> Interlock in rig
            vpp = p.tray_amp_um / gain if gain else cfg.control.start_vpp
        elif gain:
            # the tray's response per volt at this frequency is known: predict before sending
            self._check_predicted(f, gain * target_vpp, target_vpp)
            vpp = target_vpp
        else:
            # soft start: nothing predicts the tray's travel yet; ramp up while measuring it
            vpp = min(target_vpp, cfg.control.start_vpp)
        iterations = 0
        while True:
            rig.check_drive(vpp)
            self._set_sine(f, vpp, 0.0)
            self._arm_burst(f, p.settle_s, p.dwell_s)
            t_changed = time.monotonic()
            self.guard.on()
            rec, w = self._settle_and_acquire(f, p.settle_s, p.dwell_s, t_changed)
            waited += w
            tray = measure.sine_phasors(rec, f, rig.scale_mm_s_per_v, rig.velocity_delay_s)
            self._check_measured_drive(tray)
            x_um = measure.displacement_um(tray.velocity_mm_s, f)
            iterations += 1
            if x_um > cfg.tray_max_um:
                raise Interlock(f"tray displacement {x_um:.3g} um above interlock.tray_max_um = "
                                f"{cfg.tray_max_um:g} um")
            rig.check_envelope(f, x_um)
            if x_um > 0:
                self.gain_um_per_vpp[f] = x_um / vpp
            if p.tray_amp_um is None:
                if vpp >= target_vpp:
                    reason = ""
                    break
                nxt = min(target_vpp, vpp * cfg.control.max_step_ratio)
                self._check_predicted(f, x_um / vpp * nxt, nxt)
                vpp = nxt
                continue
            if abs(x_um / p.tray_amp_um - 1) <= cfg.control.tolerance:
                reason = ""
                break
            if iterations >= p.max_iterations:
                reason = (f"tray amplitude {x_um:.4g} um not within {cfg.control.tolerance:.0%} of "
                          f"{p.tray_amp_um:g} um after {iterations} adjustments")
                break
            ratio = p.tray_amp_um / x_um if x_um > 0 else cfg.control.max_step_ratio
            vpp *= min(max(ratio, 1 / cfg.control.max_step_ratio), cfg.control.max_step_ratio)
        tray_rec = rec
        self._move_spot(p.robot_spot, drive_off=False)
        robot_rec, w = self._settle_and_acquire(f, p.settle_s, p.dwell_s, time.monotonic())
        waited += w
        robot = measure.sine_phasors(robot_rec, f, rig.scale_mm_s_per_v, rig.velocity_delay_s)
        self._check_measured_drive(robot)
        from labkit.analysis.frf import transmissibility

        T, q = transmissibility(robot.velocity_re_drive, tray.velocity_re_drive,
                                robot_quality=robot.quality, tray_quality=tray.quality)
        video, frames = "", 0
        if p.video_s > 0:
            if self.bounded:     # one more burst, long enough to settle and film
                self._arm_burst(f, p.settle_s, p.video_s)
                self._fire_burst(f)
                time.sleep(p.settle_s)
            video, frames = self._video(p)
            waited += p.video_s
        self.timing.append({"waited_s": waited})
        rows: Row = {"location": p.robot_spot, "freq_hz": f, "reason": reason,
                     "tray_amp_request_um": p.tray_amp_um if p.tray_amp_um is not None else math.nan,
                     "drive_request_vpp": p.drive_vpp if p.drive_vpp is not None else math.nan,
                     "drive_vpp": vpp, "iterations": iterations, "tray_amp_um": x_um,
                     "tray_velocity_mm_s": tray.velocity_re_drive, "robot_velocity_mm_s": robot.velocity_re_drive,
                     "transmissibility": complex(T), "quality": float(q), "video": video, "video_frames": frames}
        records = ("records", tray_rec.dt_s, {
            "tray_velocity_mm_s": (tray_rec.velocity_v * rig.scale_mm_s_per_v, "mm/s"),
            "robot_velocity_mm_s": (robot_rec.velocity_v * rig.scale_mm_s_per_v, "mm/s"),
            "tray_drive_v": (tray_rec.drive_v, "V"), "robot_drive_v": (robot_rec.drive_v, "V")})
        return rows, None, records

    def _video(self, p: ShakerPoint) -> tuple[str, int]:
        """Film the point into ``<run>_videos/p<index>.mkv``: room checked first, written aside and
        renamed into place (a failed or cut recording leaves no partial video under that name)."""
        from labkit.experiments.runfile import check_free_bytes
        from labkit.outputs import atomic_output

        folder = video_folder(self.file.path)
        folder.mkdir(exist_ok=True)
        path = folder / f"p{p.index:05d}.mkv"   # Matroska keeps each frame's own timestamp
        check_free_bytes(folder, video_bytes(p.video_s), f"the video of point {p.index}")
        with atomic_output(path) as tmp:
            info = self.rig.record_video(tmp, p.video_s)
        self._event(f"video {path.name}: {info.get('frames', 0)} frames")
        rel = os.path.relpath(path, self.file.path.parent)
        frames = info.get("frames", 0)
        return rel, int(frames) if isinstance(frames, (int, float)) else 0


#: how each kind of point is measured (a step -> handler table: a plan holds only these kinds)
_MEASURE: dict[type, Callable[[Runner, Any], tuple[Row, Row | None, Any]]] = {
    SinePoint: Runner._sine_point, ChirpPoint: Runner._chirp_point, ShakerPoint: Runner._shaker_point}


#: bytes per second of video a point may write: the lab camera's 640 x 480 at 30 frames/s, one
#: byte a pixel (Motion-JPEG stays well below; the room checks count this much)
VIDEO_BYTES_PER_S = 30 * 640 * 480


def video_bytes(video_s: float) -> float:
    """Room one point's video is counted for (bytes)."""
    return float(video_s) * VIDEO_BYTES_PER_S


def video_folder(run_file: Path) -> Path:
    """Where a run's per-point videos go: ``<run file's stem>_videos`` beside it."""
    return run_file.with_name(run_file.stem + "_videos")


def _warn(text: str) -> None:
    """A warning on standard error, even with --quiet: the person at the bench must know."""
    import sys

    try:
        print(f"labkit: warning: {text}", file=sys.stderr, flush=True)
    except (OSError, ValueError):
        pass


def _nbytes(loc_rows: Row | None, records: Any) -> float:
    """Bytes a point's rows and records take (records are stored as float32)."""
    n = 0.0
    for v in (loc_rows or {}).values():
        n += np.asarray(v).nbytes if not isinstance(v, str) else len(v)
    if records is not None:
        for data, _units in records[2].values():
            n += np.asarray(data).size * 4
    return n
