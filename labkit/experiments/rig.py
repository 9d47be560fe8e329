"""The rig: the open instruments of one experiment, set up from a validated config.

Only the runner uses a rig. Limits are handed to the drivers so they are
checked before anything is sent: the PZT voltage limit becomes the
generator's ``max_v`` in-chip; the amplifier's input cap for its declared gain
becomes the generator's ``max_amp_vpp`` on the shaker.

The laser spot is moved by a :class:`LabSpot` (the virtual lab's control
channel) or a :class:`PromptSpot` (asks the person at the terminal).
"""
from __future__ import annotations

import logging
import sys
from typing import TYPE_CHECKING, Any, TextIO, cast

from labkit.errors import DriveNotOff, InputError, InstrumentError, LimitError
from labkit.experiments import kinds
from labkit.experiments.config import VIB_OUTPUT_MAX_V, InstrumentSpec
from labkit.experiments.kinds import Config
from labkit.experiments.protocols import (
    Amplifier,
    Camera,
    FunctionGenerator,
    Scope,
    ShakerEnvelope,
    SpotMover,
    Vibrometer,
)
from labkit.experiments.safety import RECONNECT_WINDOW_S, DriveGuard, Interlock
from labkit.jsonutil import Json

if TYPE_CHECKING:  # pragma: no cover
    from labkit.lab.client import LabControl

#: closing the rig on the shutdown path (``labkit -v`` shows what failed)
_log = logging.getLogger(__name__)

#: scope vertical divisions on screen (both supported models have 8)
VERTICAL_DIVS = 8


class PromptSpot:
    """Ask the person to point the laser (drive is off while they do)."""

    def __init__(self, stdin: TextIO | None = None, stderr: TextIO | None = None) -> None:
        self.stdin = stdin or sys.stdin
        self.stderr = stderr or sys.stderr

    def move(self, spot: str) -> None:
        print(f"\n>>> Point the laser vibrometer at the {spot.upper()} and press Enter "
              f"(Ctrl-C stops the run safely) ", file=self.stderr, end="", flush=True)
        line = self.stdin.readline()
        if not line:
            raise InputError(f"no answer on standard input when asked to point the laser at the {spot}",
                             key="instruments.control",
                             expected="a terminal to answer on, or an [instruments.control] virtual-lab channel")


class LabSpot:
    """Tell the virtual lab where the laser points (``LAB:SPOT``)."""

    def __init__(self, control: LabControl) -> None:
        self.control = control

    def move(self, spot: str) -> None:
        self.control.set_spot(spot)


def _open(spec: InstrumentSpec, **extra: Any) -> Any:
    from labkit.drivers.registry import open_instrument

    settings = dict(spec.settings)
    for k, v in extra.items():
        if v is None:
            continue
        if k in settings and isinstance(settings[k], (int, float)) and k.startswith("max"):
            settings[k] = min(float(settings[k]), float(v))   # the stricter limit wins
        else:
            settings[k] = v
    try:
        inst = open_instrument(spec.model, spec.resource, name=spec.role, **settings)
    except LimitError:
        raise
    except InputError as exc:
        raise type(exc)(exc.message, file=exc.file, key=f"instruments.{spec.role}." + (exc.key or "model"),
                        expected=exc.expected) from None
    return inst


def _open_plain(spec: InstrumentSpec) -> Any:
    """The generator's driver on a new link that skips the handshake (only OFF is sent on it)."""
    from labkit.drivers.registry import driver_class

    cls = driver_class(spec.model)
    plain: Any = type(cls.__name__, (cls,), {"connect_on_open": False})
    settings = {k: v for k, v in spec.settings.items() if not k.startswith("max")}
    return plain.open(spec.resource, name=spec.role, **settings)


def _off_without_handshake(spec: InstrumentSpec, exc: InstrumentError, config: str) -> InstrumentError:
    """The generator failed while connecting: send its OFF on a fresh link that skips the handshake.

    Returns the error to raise: ``exc`` (exit 3) when the OFF was confirmed (or no link could
    be opened at all: nothing answered at that address), else
    :class:`DriveNotOff` (exit 4, the banner): an output left on by an earlier session must
    not go unmentioned because the link failed before the run could turn it off.
    """
    import time


    if exc.command == "open":       # no link at all (nothing answers there): exit 3, as before
        return exc
    last: Exception = exc
    t0 = time.monotonic()
    while True:
        try:
            with _open_plain(spec) as fg:   # __exit__: safe_off, close
                fg.safe_off()
            return exc
        except (InstrumentError, InputError) as again:
            last = again
        if time.monotonic() - t0 > RECONNECT_WINDOW_S:
            break
        time.sleep(0.2)
    return DriveNotOff("funcgen", f"{spec.model} at {spec.resource}", str(last),
                       original=f"the generator failed while connecting: {exc}", config=config)


def _reopen_within(spec: InstrumentSpec, window_s: float) -> Any:
    """A new connection to ``spec``'s instrument, tried until ``window_s`` has passed."""
    import time

    t0 = time.monotonic()
    while True:
        try:
            return _open(spec)
        except InstrumentError:
            if time.monotonic() - t0 > window_s:
                raise
        time.sleep(0.1)


def _claim(inst: Any, spec: InstrumentSpec) -> None:
    """Lock the instrument by its ``*IDN?`` identity before anything else is sent to it; on
    RigBusy (another run has it, spelled differently) only the link is closed."""
    from labkit.experiments.locks import claim_identity

    try:
        claim_identity(spec.role, str(inst.identity), spec.resource)
    except BaseException:
        inst.close()
        raise


class Rig:
    """Open instruments for one run (use as a context manager: everything is closed at exit).

    The generator belongs to the rig's :class:`DriveGuard` (``rig.guard``): the guard alone
    turns its output on and off and replaces the connection when the link is lost;
    ``rig.funcgen`` is always the guard's current connection.
    """

    def __init__(self, cfg: Config, *, spot: SpotMover | None = None) -> None:
        self.cfg = cfg
        self.kind = kinds.of(cfg)
        self.setup = self.kind.rig_setup(cfg)
        # guard, scope and vibrometer exist once open() has run (they are needed by every run)
        self.control: LabControl | None = None
        self.camera: Camera | None = None
        self.amplifier: Amplifier | None = None
        self.envelope: ShakerEnvelope | None = None
        self.max_drive_vpp: float | None = None
        self.drive_channel = cfg.scope.drive_channel
        self.velocity_channel = cfg.scope.velocity_channel
        self.scale_mm_s_per_v = cfg.scale_mm_s_per_v
        self.velocity_delay_s = 0.0
        self._trigger_source = "EXT"        # resolved per scope model when the scope opens
        self._spot = spot
        self._funcgen_limits: dict[str, float] = {}
        self.velocity_vpd = cfg.scope.velocity_volts_per_div or 2 * VIB_OUTPUT_MAX_V / VERTICAL_DIVS
        self.drive_vpd: float | None = None
        self._points: int | None = None
        self._at: str | None = None                  # where the laser points
        self._range_at: dict[str, float] = {}        # velocity V/div last used per spot
        self.identities: dict[str, str] = {}          # role -> *IDN? at open (a reconnect must match it)

    guard: DriveGuard
    scope: Scope
    vibrometer: Vibrometer

    @property
    def funcgen(self) -> FunctionGenerator:
        """The generator's current connection (owned by :attr:`guard`)."""
        return self.guard.funcgen

    # -- opening ---------------------------------------------------------------------------
    def open(self) -> Rig:
        cfg = self.cfg
        inst = cfg.instruments
        setup = self.setup
        try:
            if "control" in inst:
                from labkit.lab.client import LabControl

                self.control = LabControl(inst["control"].resource)
                self.control.set_setup(self.kind.lab_setup)
            self.amplifier, self.envelope = setup.amplifier, setup.envelope
            if self.amplifier is not None:
                self.max_drive_vpp = float(self.amplifier.max_input_vpp)
            self._funcgen_limits = dict(setup.funcgen_limits)
            spec = inst["funcgen"]
            try:
                fg = _open(spec, **self._funcgen_limits)
            except InstrumentError as exc:      # the handshake failed: is its output off?
                raise _off_without_handshake(spec, exc, cfg.path) from exc
            _claim(fg, spec)
            self.identities["funcgen"] = str(fg.identity)
            self.guard = DriveGuard(fg, reopen=self.reopen_funcgen, where=f"{spec.model} at {spec.resource}",
                                    config=cfg.path)
            # A generator may come up with its output on from an earlier session: off first.
            fg.safe_off()
            fg.set_load()         # the declared load_ohm (INF: the PZT, an amplifier input), read back
            scope = _open(inst["scope"])
            _claim(scope, inst["scope"])
            self.identities["scope"] = str(scope.identity)
            self.scope = scope
            # EXT where the scope has it, else the drive; EXT on a model without it: ConfigError, nothing set
            self._trigger_source = scope.trigger_source_for(cfg.scope.trigger_source, self.drive_channel)
            vib = self.vibrometer = _open(inst["vibrometer"])
            vib.scale_mm_s_per_v = cfg.scale_mm_s_per_v
            self.scale_mm_s_per_v = float(vib.scale_mm_s_per_v)
            # the decoder's output lags the velocity: every point's phase is corrected for it
            self.velocity_delay_s = float(vib.signal_delay_s)
            self._set_up_scope()
            if setup.wants_camera:
                self.camera = self._open_camera()
            if self._spot is None:
                self._spot = LabSpot(self.control) if self.control is not None else PromptSpot()
        except BaseException:
            self.close()
            raise
        return self

    def _set_up_scope(self) -> None:
        """The scope's channels, trigger and averaging, and the generator's sync (after open or a reconnect)."""
        scope, cfg, setup = self.scope, self.cfg, self.setup
        scope.poll_s = 0.002       # completion polls: fine-grained (the record time is slept)
        scope.setup_channel(self.velocity_channel, self.velocity_vpd, 0.0, "DC")
        trig = self._trigger_source
        # EXT: the generator's TTL sync (phase zero of the sine, start of a sweep)
        offset_v = setup.drive[1] if setup.drive is not None else 0.0
        level = 1.0 if trig == "EXT" else (offset_v if trig == f"CHAN{self.drive_channel}" else 0.0)
        if trig == "EXT":
            self.funcgen.enable_sync()      # sync on, from the drive channel, read back (docs/instruments.md)
        scope.set_trigger(trig, level, "POS")     # NORMal sweep: no trigger, no record
        # scope.averages records per point, read back (1: a scope left averaging would blend points)
        scope.set_averaging(cfg.scope.averages)
        self._points = self.drive_vpd = None
        if setup.drive is not None:
            self.on_drive_amplitude(*setup.drive)

    def reconnect(self, role: str, window_s: float) -> None:
        """Replace the lost link to ``role`` (funcgen or scope) within ``window_s`` seconds.

        The instrument that answers must be the one the run locked (``*IDN?`` maker, model
        and serial); the generator's output must read back off (its OFF is sent first, on the
        new link); then the settings the run depends on are sent again. Raises
        InstrumentError when no link came back in time or another instrument answered.
        """
        from labkit.experiments.locks import identity_key

        spec = self.cfg.instruments[role]
        if role == "funcgen":
            self.guard.final_off(f"the {role}'s link was lost: reconnecting")    # reopens, OFF confirmed
            new: Any = self.guard.funcgen
        else:
            new = _reopen_within(spec, window_s)
        got, want = str(new.identity), self.identities[role]
        if (identity_key(got) or got) != (identity_key(want) or want):
            raise InstrumentError(f"another instrument answered at {spec.resource} after the link was lost: "
                                  f"{got[:60]!r}, not {want[:60]!r}", instrument=role, command="*IDN?")
        if role == "funcgen":
            if not getattr(self.guard.funcgen, "connect_on_open", True):   # the OFF's link without handshake
                raise InstrumentError("the generator answers the OFF but not its handshake",
                                      instrument=role, command="*IDN?")
            if self.guard.funcgen.output_on:
                raise InstrumentError("the output reads on after the reconnect's OFF", instrument=role,
                                      command="OUTP?")
            self.guard.funcgen.set_load()
            if self.cfg.scope.trigger_source == "EXT":
                self.guard.funcgen.enable_sync()
        else:
            old, self.scope = self.scope, new
            old.close()
            self._set_up_scope()

    def _open_camera(self) -> Camera:
        spec = self.cfg.instruments.get("camera")
        if spec is None or spec.model == "LabCamera":
            from labkit.lab.client import LabCamera

            resource = spec.resource if spec is not None else self.cfg.instruments["control"].resource
            return LabCamera(resource)
        import labkit.drivers.camera as cam

        if spec.model == "OpenCVCamera":
            return cam.OpenCVCamera(**spec.settings)
        if spec.model == "FileCamera":
            return cam.FileCamera(spec.resource or str(spec.settings.get("path", "")))
        raise InputError(f"unknown camera model {spec.model!r}", file=self.cfg.path,
                         key="instruments.camera.model", expected="LabCamera, OpenCVCamera or FileCamera")

    def set_record_points(self, points: int) -> None:
        """Points per record (sent now so the next record has them; unchanged counts are not resent)."""
        points = int(max(100, min(points, self.cfg.scope.max_points)))
        if self._points == points:
            return
        self.scope.set_record_points(points)
        self._points = points

    def chirp_timebase(self, length_s: float) -> None:
        """Record exactly the sweep: the trigger (sweep start) at the record's first sample."""
        self.scope.set_timebase(length_s)
        self.scope.set_trigger_at_start(length_s)

    def reopen_funcgen(self) -> FunctionGenerator:
        """A new connection to the generator (the old link was lost); the guard adopts it.

        When the handshake fails on it (an error queue that does not answer, say), a link
        without the handshake is returned instead: the OFF must get through all the same."""
        spec = self.cfg.instruments["funcgen"]
        try:
            return _open(spec, **self._funcgen_limits)
        except InstrumentError as exc:
            if exc.command == "open":       # nothing answers at that address
                raise
            return cast(FunctionGenerator, _open_plain(spec))

    def close(self) -> None:
        for name in ("camera", "vibrometer", "scope", "control", "guard"):
            obj = self.__dict__.get(name)      # only what open() got to
            if obj is None:
                continue
            try:
                obj.close()
            except Exception as exc:
                _log.info("closing the %s: %s: %s", name, type(exc).__name__, exc)

    def __enter__(self) -> Rig:
        return self.open()

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # -- what the runner asks --------------------------------------------------------------
    def move_spot(self, spot: str) -> None:
        """Move the laser; the velocity channel gets back the range it last had at that spot."""
        if self._at is not None:
            self._range_at[self._at] = self.velocity_vpd
        if self._spot is None:      # open() always sets one; a rig used unopened asks the person
            self._spot = PromptSpot()
        self._spot.move(spot)
        self._at = spot
        want = self._range_at.get(spot)
        if want is not None and want != self.velocity_vpd:
            self._set_velocity_vpd(want)

    def on_drive_amplitude(self, amp_vpp: float, offset_v: float) -> None:
        """Fit the drive channel's vertical scale to the drive (only when it changes much)."""
        want = self.cfg.scope.drive_volts_per_div or max(amp_vpp * 1.25 / VERTICAL_DIVS, 1e-3)
        if self.drive_vpd is not None and 0.5 <= want / self.drive_vpd <= 1.0:
            return                      # still on screen with fair resolution
        self.scope.setup_channel(self.drive_channel, want, offset_v, "DC")
        self.drive_vpd = want

    def velocity_clipped(self, volts: Any) -> bool:
        import numpy as np

        half = self.velocity_vpd * VERTICAL_DIVS / 2
        peak = float(np.max(np.abs(volts)))
        if peak < 0.2 * half and self.cfg.scope.velocity_volts_per_div is None:
            # Small signal: narrow the range for the next point (better resolution).
            self._set_velocity_vpd(max(peak * 2.5 / VERTICAL_DIVS * 2, 1e-3))
            return False
        return peak >= 0.98 * half

    def widen_velocity_range(self) -> bool:
        """Widen the velocity channel after clipping; False when already at the vibrometer's full range."""
        full = 2 * VIB_OUTPUT_MAX_V / VERTICAL_DIVS
        if self.velocity_vpd >= full:
            return False
        self._set_velocity_vpd(min(self.velocity_vpd * 4, full))
        return True

    def _set_velocity_vpd(self, vpd: float) -> None:
        self.scope.setup_channel(self.velocity_channel, vpd, 0.0, "DC")
        self.velocity_vpd = vpd

    def check_drive(self, vpp: float) -> None:
        """Interlock when a drive above the amplifier's input cap would be needed (nothing sent)."""
        cap = self.max_drive_vpp
        if cap is not None and vpp > cap:
            raise Interlock(f"drive {vpp:.4g} Vpp needed exceeds the amplifier input cap {cap:.4g} Vpp "
                            f"at {self.amplifier.gain_db if self.amplifier else float('nan'):g} dB gain")

    def check_envelope(self, freq_hz: float, disp_amp_um: float) -> None:
        """Interlock when the shaker's stroke/velocity/force/frequency envelope would be exceeded."""
        if self.envelope is None:
            return
        try:
            self.envelope.check(freq_hz, disp_amp_um, payload_kg=self.setup.payload_kg)
        except LimitError as exc:
            raise Interlock(f"shaker envelope: {exc.message}") from None

    def record_video(self, path: Any, duration_s: float) -> dict[str, Json]:
        if self.camera is None:
            raise InstrumentError("no camera", instrument="camera", command="record")
        return self.camera.record(str(path), duration_s)

    def snapshots(self) -> dict[str, tuple[str, str, dict[str, Json]]]:
        """role -> (model, resource, snapshot) for the run file."""
        out: dict[str, tuple[str, str, dict[str, Json]]] = {}
        opened: dict[str, FunctionGenerator | Scope | Vibrometer] = {
            "funcgen": self.funcgen, "scope": self.scope, "vibrometer": self.vibrometer}
        for role, obj in opened.items():
            spec = self.cfg.instruments[role]
            out[role] = (spec.model, spec.resource, obj.snapshot())
        if self.control is not None:
            spec = self.cfg.instruments["control"]
            out["control"] = (spec.model, spec.resource, {"resource": spec.resource})
        if self.amplifier is not None:
            out["amplifier"] = ("2718 (declared)", "", self.amplifier.snapshot() | {
                "max_drive_vpp": self.max_drive_vpp})
        if self.envelope is not None:
            out["shaker"] = ("4809 (declared)", "", self.envelope.snapshot() | {"payload_kg": self.setup.payload_kg})
        if self.camera is not None:
            cam = self.cfg.instruments.get("camera")
            out["camera"] = (cam.model if cam else "LabCamera", cam.resource if cam else "", self.camera.snapshot())
        return out
