"""The live stream of a run: one JSON line per point and per event, beside the run file.

The run (the only owner of the instruments and of the run file) appends to
``RUN.live.jsonl`` and flushes after every line, so any number of readers
(``labkit watch``, ``labkit view``) follow it without touching the run file or
the instruments, join late, and replay a finished run from its first line.
Records (``"t"`` names the type; times are Unix seconds; NaN is written ``null``):

``start``
    ``pid``, ``file``, ``kind``, ``points_planned``, ``points_done`` (a resumed
    run starts with some), ``est_s`` (the plan's estimate of what is left),
    ``locations``, ``quality_min``, ``heartbeat_s``, ``config`` (its path, for ``labkit off``).
``point``
    ``k`` of ``n``, ``index`` (plan index), ``location``, ``freq_hz``,
    ``status`` (``ok`` | ``interlock``), ``reason``, ``elapsed_s``,
    ``remaining_s``; an in-chip point adds ``frf`` (``[re, im]``, (mm/s)/V),
    ``quality``, ``drive_vpp`` (measured) and ``drive_set_vpp``; a shaker point
    adds ``tray_amp_um`` and its request, ``drive_vpp`` (applied) and
    ``drive_measured_vpp`` (in its last record), ``transmissibility``,
    ``robot_velocity_mm_s`` (``[re, im]``) and ``video``; a chirp point has
    arrays (``freq_hz``, ``frf`` as ``[[re...], [im...]]``, ``quality``). Every
    point with a scope record adds ``pct_fs`` (peak of each channel, % of the
    scope's full scale), ``over`` (clipped, or the vibrometer over range) and
    ``under`` (below :data:`UNDER_PCT` of full scale) per channel.
``event``
    ``text`` (the same line as the run file's ``/events``); drive events add
    ``drive`` (true: on, false: off).
``hb``
    the heartbeat, every :data:`HEARTBEAT_S` from a thread of the run:
    ``busy_s`` (time since the run's last record: a long settle, or a hang).
``end``
    ``status`` (as the run file's) and ``exit`` (the exit code ``labkit`` returns).

A stop request (``labkit view``'s Stop "after this point") is a file
``RUN.live.stop`` the run looks for before each point; "now" is SIGINT.
"""
from __future__ import annotations

import contextlib
import contextvars
import json
import math
import os
import sys
import threading
import time
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from labkit.jsonutil import Json
from labkit.lockfiles import LockRecord

#: one line of the stream: a JSON object (``t`` says which record: start, hb, event, point, end)
Record = dict[str, Json]

#: seconds between heartbeat lines
HEARTBEAT_S = 1.0
#: a reader calls the run "not responding" when the last line is older than this
STALE_S = 5.0
#: the sine-fit R^2 under which a point is shown as poor (the residual is a tenth of the record's power)
QUALITY_MIN = 0.9
#: a channel whose peak is under this percentage of the scope's full scale is flagged under range
UNDER_PCT = 10.0
#: a channel at or above this percentage of full scale is clipped
OVER_PCT = 98.0


def live_path(run_path: str | Path) -> Path:
    """``RUN.live.jsonl`` beside ``RUN.h5``."""
    p = Path(run_path)
    return p.with_name(p.stem + ".live.jsonl")


def stop_path(run_path: str | Path) -> Path:
    """The stop request file (``RUN.live.stop``) the run looks for before each point."""
    p = Path(run_path)
    return p.with_name(p.stem + ".live.stop")


def num(x: Any) -> float | None:
    """A float for JSON: None when not finite."""
    x = float(x)
    return x if math.isfinite(x) else None


def _cplx(z: Any) -> list[Json]:
    z = complex(z)
    return [num(z.real), num(z.imag)]


def _magnitude(z: Any) -> float:
    return abs(complex(z))


def exit_code_of(exc: BaseException | None) -> int:
    """The exit code ``labkit`` gives a run that ended with ``exc`` (None: success)."""
    from labkit.errors import EXIT_INTERRUPTED, Interrupted, LabkitError

    if exc is None:
        return 0
    if isinstance(exc, (KeyboardInterrupt, Interrupted)):
        return EXIT_INTERRUPTED
    return int(getattr(exc, "exit_code", 1)) if isinstance(exc, LabkitError) else 1


@dataclass
class Scope:
    """What a point's record looked like on the scope: peak per channel, % of full scale."""

    drive_pct: float
    velocity_pct: float
    drive_vpp: float = math.nan      # the drive's peak-to-peak from its rms (a sine's: 2 sqrt(2) rms)


def record_levels(drive_v: Any, velocity_v: Any, drive_fs_v: float | None, velocity_fs_v: float | None) -> Scope:
    """Peaks of a record's two channels as a percentage of each channel's half range (NaN: unknown).

    The half range is what the screen shows above (or below) its centre: V/div x divisions / 2."""
    import numpy as np

    def pct(v: Any, fs: float | None) -> float:
        v = np.asarray(v, float)
        # about the record's mean: the drive channel is centred on the generator's DC offset
        return float(np.max(np.abs(v - v.mean()))) / fs * 100 if fs and v.size else math.nan

    d = np.asarray(drive_v, float)
    vpp = 2 * math.sqrt(2) * float(np.std(d)) if d.size else math.nan
    return Scope(pct(drive_v, drive_fs_v), pct(velocity_v, velocity_fs_v), vpp)


class LiveStream:
    """Writer of a run's live stream (the runner's observer), with its heartbeat thread.

    Parameters
    ----------
    run_path:
        The run file; the stream is :func:`live_path` of it (appended to: a resumed
        run continues its stream).
    console:
        Where to print a row per point and event as well (the run's console when it
        is not a terminal), or None.
    """

    def __init__(self, run_path: str | Path, console: IO[str] | None = None) -> None:
        self.path = live_path(run_path)
        self.run_name = Path(run_path).name
        self.stop_file = stop_path(run_path)
        self.console = console
        self.cost_s = 0.0              # time the run spent on points and events (bench/run_bench.py)
        self.points = 0
        self._lock = threading.Lock()
        self._last = time.monotonic()
        self._t0 = time.time()
        self._k = 0
        self._n = 0
        self._session = 0               # points measured since this start (for remaining_s)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._f: IO[str] | None = None

    # -- writing -----------------------------------------------------------------------------
    def _write(self, rec: Record, beat: bool = False) -> None:
        line = json.dumps(rec, separators=(",", ":"), allow_nan=False)
        with self._lock:
            if self._f is None:
                return
            try:
                self._f.write(line + "\n")
                self._f.flush()
            except (OSError, ValueError):   # a full disk must not stop the run (the run file decides)
                return
            if not beat:
                self._last = time.monotonic()
        if self.console is not None and not beat:
            row = format_record(rec)
            if row:
                try:
                    print(row, file=self.console, flush=True)
                except (OSError, ValueError):
                    self.console = None

    def start(self, *, kind: str, points_planned: int, points_done: int, est_s: float,
              locations: list[str], config: str = "") -> None:
        """Open the stream (append), write the ``start`` record, start the heartbeat."""
        try:
            self.stop_file.unlink()           # a request left from an earlier run must not stop this one
        except OSError:
            pass
        try:
            self._f = open(self.path, "a", encoding="utf-8")
        except OSError:
            self._f = None                    # no live view, but the run goes on
        self._t0 = time.time()
        self._k, self._n = points_done, points_planned
        self._write({"t": "start", "time": self._t0, "pid": os.getpid(), "file": self.run_name,
                     "kind": kind, "points_planned": points_planned, "points_done": points_done,
                     "est_s": num(est_s), "locations": list[Json](locations), "quality_min": QUALITY_MIN,
                     "heartbeat_s": HEARTBEAT_S, "config": config})
        self._thread = threading.Thread(target=self._beat, name="labkit-live-heartbeat", daemon=True)
        self._thread.start()

    def _beat(self) -> None:
        while not self._stop.wait(HEARTBEAT_S):
            self._write({"t": "hb", "time": time.time(), "busy_s": round(time.monotonic() - self._last, 3)},
                        beat=True)

    def event(self, text: str) -> None:
        t = time.perf_counter()
        rec: Record = {"t": "event", "time": time.time(), "text": text}
        if text.startswith("drive on"):
            rec["drive"] = True
        elif text.startswith("drive off"):
            rec["drive"] = False
        self._write(rec)
        self.cost_s += time.perf_counter() - t

    def point(self, index: int, rows: Mapping[str, object], loc: Mapping[str, object] | None, scope: Scope | None,
              *, drive_set_vpp: float | None = None, over_range: bool = False) -> None:
        """Write one finished point (``rows``: its ``/points`` row; ``loc``: its location rows)."""
        t = time.perf_counter()
        self._k += 1
        self._session += 1
        elapsed = time.time() - self._t0
        rec: Record = {"t": "point", "time": time.time(), "k": self._k, "n": self._n, "index": int(index),
                       "location": str(rows.get("location", "")), "status": str(rows.get("status", "")),
                       "reason": str(rows.get("reason", "")), "elapsed_s": round(elapsed, 3),
                       "remaining_s": round(elapsed / self._session * max(self._n - self._k, 0), 3)}
        rec["freq_hz"] = num(rows.get("freq_hz", math.nan))
        if loc is not None:
            rec.update(_location_fields(loc, drive_set_vpp))
        if "tray_amp_um" in rows:
            rec.update(_shaker_fields(rows))
        if scope is not None:
            pct = {"drive": num(scope.drive_pct), "velocity": num(scope.velocity_pct)}
            rec["pct_fs"] = {k: v for k, v in pct.items()}
            rec["over"] = {"drive": (pct["drive"] or 0) >= OVER_PCT,
                           "velocity": over_range or (pct["velocity"] or 0) >= OVER_PCT}
            rec["under"] = {k: v is not None and v < UNDER_PCT for k, v in pct.items()}
            if "tray_amp_um" in rec:        # a shaker point: the drive the scope saw in its last record
                rec["drive_measured_vpp"] = num(scope.drive_vpp)
        elif over_range:
            rec["over"] = {"drive": False, "velocity": True}
        self._write(rec)
        self.points += 1
        self.cost_s += time.perf_counter() - t

    def end(self, status: str, exc: BaseException | None) -> None:
        """The ``end`` record (status and exit code); stops the heartbeat and closes the stream."""
        self._write({"t": "end", "time": time.time(), "status": status, "exit": exit_code_of(exc)})
        self.close()
        try:
            self.stop_file.unlink()       # a "now" request (or one too late) has been answered
        except OSError:
            pass

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=2 * HEARTBEAT_S)
        with self._lock:
            if self._f is not None:
                try:
                    self._f.close()
                except OSError:
                    pass
                self._f = None

    # -- the stop request ------------------------------------------------------------------------
    def stop_requested(self) -> str | None:
        """The text of a pending stop request (the file is removed), or None."""
        try:
            text = self.stop_file.read_text(encoding="utf-8", errors="replace").strip()
        except OSError:
            return None
        try:
            self.stop_file.unlink()
        except OSError:
            pass
        return text or "stop requested"


def _location_fields(loc: Mapping[str, object], drive_set_vpp: float | None) -> Record:
    import numpy as np

    f = np.asarray(loc["freq_hz"])
    if f.ndim:          # a chirp: every frequency line at once
        h = np.asarray(loc["frf"])
        return {"freq_hz": [num(x) for x in f], "frf": [[num(x) for x in h.real], [num(x) for x in h.imag]],
                "quality": [num(x) for x in np.asarray(loc["quality"])]}
    out: Record = {"frf": _cplx(loc["frf"]), "quality": num(loc["quality"])}
    if "drive_v" in loc:
        out["drive_vpp"] = num(2 * _magnitude(loc["drive_v"]))
        out["drive_set_vpp"] = num(drive_set_vpp) if drive_set_vpp is not None else None
    return out


def _shaker_fields(rows: Mapping[str, object]) -> Record:
    return {"tray_amp_um": num(rows["tray_amp_um"]), "tray_amp_request_um": num(rows["tray_amp_request_um"]),
            "drive_vpp": num(rows["drive_vpp"]), "drive_request_vpp": num(rows["drive_request_vpp"]),
            "transmissibility": _cplx(rows["transmissibility"]), "quality": num(rows["quality"]),
            "robot_velocity_mm_s": _cplx(rows["robot_velocity_mm_s"]), "video": str(rows.get("video", ""))}


# -- reading ---------------------------------------------------------------------------------------
def follow(path: str | Path, offset: int = 0, *, wait: bool = True, poll_s: float = 0.1,
           timeout_s: float | None = None) -> Iterator[tuple[int, Record]]:
    """Yield ``(offset after the line, record)`` from ``offset`` on; with ``wait``, follow the file
    until an ``end`` record (or ``timeout_s`` without a new line). Half-written last lines wait."""
    path = Path(path)
    buf = b""
    quiet_since = time.monotonic()
    while True:
        try:
            with open(path, "rb") as f:
                f.seek(offset + len(buf))
                chunk = f.read()
        except FileNotFoundError:
            chunk = b""
        buf += chunk
        ended = False
        while b"\n" in buf:
            line, buf = buf.split(b"\n", 1)
            offset += len(line) + 1
            try:
                rec = json.loads(line)
            except ValueError:
                continue
            if not isinstance(rec, dict):
                continue
            yield offset, rec
            ended = rec.get("t") == "end"
        if chunk:
            quiet_since = time.monotonic()
        if ended or not wait or (timeout_s is not None and time.monotonic() - quiet_since > timeout_s):
            return
        time.sleep(poll_s)


def stream_of(path: str | Path) -> tuple[Path, Path]:
    """``(run file, live stream)`` for a run file or its stream; InputError (exit 2) when there is no stream."""
    from labkit.errors import InputError

    p = Path(path)
    if p.name.endswith(".live.jsonl"):
        p = p.with_name(p.name[: -len(".live.jsonl")] + ".h5")
    stream = live_path(p)
    if not stream.is_file():
        if not p.exists() and not p.parent.is_dir():
            raise InputError("the folder does not exist", file=p)
        raise InputError(f"no live stream beside it (expected {stream.name}; every run writes one as it starts)",
                         file=p, expected="a run file of a run started with this labkit, or its .live.jsonl")
    return p, stream


def run_holder(run_path: str | Path) -> LockRecord | None:
    """The lock record (pid, command, ...) of the process writing ``run_path`` now, or None."""
    from labkit.lockfiles import file_key, holder

    return holder(file_key(run_path))


def _db(z: Json) -> str:
    re_, im = (_number(z[0]), _number(z[1])) if isinstance(z, list) and len(z) == 2 else (0.0, 0.0)
    mag = math.hypot(re_, im)
    return f"{20 * math.log10(mag):6.1f} dB {math.degrees(math.atan2(im, re_)):7.1f} deg" if mag > 0 else "   -inf dB"


def _number(v: Json) -> float:
    """A number of a record (0 when it is null or not a number)."""
    return float(v) if isinstance(v, (int, float)) else 0.0


def _object(v: Json) -> dict[str, Json]:
    """A JSON object of a record (empty when it is missing or not an object)."""
    return v if isinstance(v, dict) else {}


def format_record(rec: Record) -> str | None:
    """One console row for a record (``labkit watch``, and the run's console off a terminal); None for heartbeats."""
    t = rec.get("t")
    stamp = time.strftime("%H:%M:%S", time.localtime(_number(rec.get("time"))))
    if t == "start":
        return (f"{stamp} start {rec.get('file')}: {rec.get('kind')}, {rec.get('points_done')} of "
                f"{rec.get('points_planned')} points done, pid {rec.get('pid')}")
    if t == "event":
        return f"{stamp}   {rec.get('text')}"
    if t == "end":
        return f"{stamp} end: {rec.get('status')} (exit {rec.get('exit')})"
    if t != "point":
        return None
    head = f"{stamp} {rec.get('k'):>4}/{rec.get('n'):<4} {rec.get('location', ''):<5}"
    f = rec.get("freq_hz")
    if isinstance(f, list):
        head += f" chirp {f[0]:g}-{f[-1]:g} Hz, {len(f)} lines" if f else " chirp"
    elif f is not None:
        head += f" {f:9.2f} Hz"
    if rec.get("status") != "ok":
        return f"{head}  {rec.get('status')}: {rec.get('reason')}"
    return "  ".join([head, *_point_parts(rec)])


def _point_parts(rec: Record) -> list[str]:
    """The measured values of a good point's row: response, quality, range, and the flags."""
    parts = []
    if "tray_amp_um" in rec:
        want = rec.get("tray_amp_request_um")
        parts.append(f"tray {rec['tray_amp_um'] or math.nan:.3g} um" + (f" (want {want:g})" if want else ""))
        parts.append(f"drive {rec.get('drive_vpp') or math.nan:.3g} Vpp")
        parts.append(f"T {_db(rec['transmissibility'])}")
    elif isinstance(frf := rec.get("frf"), list) and frf and not isinstance(frf[0], list):
        parts.append(f"|H| {_db(frf)}")
        if rec.get("drive_vpp") is not None:
            parts.append(f"drive {rec['drive_vpp']:.3g} Vpp")
    q = rec.get("quality")
    if isinstance(q, (int, float)):
        parts.append(f"q {q:.3f}" + (" LOW" if q < QUALITY_MIN else ""))
    pct = _object(rec.get("pct_fs"))
    if pct.get("velocity") is not None:
        parts.append(f"vel {pct['velocity']:.0f}% FS")
    flags = [f"{k} OVER" for k, v in _object(rec.get("over")).items() if v]
    return parts + flags + [f"{k} under" for k, v in _object(rec.get("under")).items() if v]


#: False inside :func:`no_console_rows` (the demo and the sample data print their own stages)
_ROWS: contextvars.ContextVar[bool] = contextvars.ContextVar("labkit_console_rows", default=True)


@contextlib.contextmanager
def no_console_rows() -> Iterator[None]:
    """Runs started inside this block print no row per point (their live stream is written as ever)."""
    token = _ROWS.set(False)
    try:
        yield
    finally:
        _ROWS.reset(token)


def console_for_run(quiet: bool) -> IO[str] | None:
    """Standard output when it is not a terminal (a row per point there) and not ``quiet``; else None."""
    if quiet or not _ROWS.get():
        return None
    try:
        return None if sys.stdout.isatty() else sys.stdout
    except (AttributeError, ValueError):
        return None
