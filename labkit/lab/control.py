"""The lab's control channel (resource ``control``): what a person at the bench would do by hand.

A small SCPI-like language on a raw socket, so ``labkit lab serve`` users and
the experiment runner can move the laser, change the set-up, arm faults and
film without Python access:

=====================================  =============================================
``LAB:SPOT BODY|HIP|KNEE|TRAY``        point the laser; ``LAB:SPOT?`` -> ``KNEE``
``LAB:SETup INCHip|SHAKer``            ``LAB:SETup?`` -> ``INCHIP``
``LAB:FAULT <inst>,<kind>[,<after>[,"<match>"[,<count>]]]``  arm a fault
``LAB:FAULT:CLEar [<inst>]``           disarm faults
``LAB:TRUTh?``                         the lab's truth as one JSON line
``LAB:OUTPut? <inst>,<ch>``            last output state from the timeline (0/1)
``CAM:FPS <fps>``                      ``CAM:FPS?``
``CAM:REC "<name>",<duration_s>``      film into CAM:DIR?/<name>; answers ``<frames>`` (0: failed, see SYST:ERR?)
``CAM:DIRectory?``                     the only folder the camera writes to
``CAM:TIMEstamps?``                    the last recording's frame times, s
=====================================  =============================================
"""
from __future__ import annotations

import json
import threading
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, TypedDict

from labkit import __version__
from labkit.jsonutil import Json, to_jsonable
from labkit.lab.scpi import Call, ScpiError, SimScpiInstrument, fmt_num

if TYPE_CHECKING:
    from labkit.lab.camera import Recording


class TetheredModes(TypedDict):
    """The tethered robot's modes in the lab (what an in-chip sweep should find)."""

    names: list[str]
    freq_hz: list[float]
    damping_ratio: list[float]


class LabTruth(TypedDict):
    """What the lab really is (``LAB:TRUTh?``, one JSON line): modes, mode shapes, chain, robot."""

    setup: str
    spot: str
    seed: int
    tethered_modes: TetheredModes
    mode_shapes_mm_s_per_v: dict[str, list[float]]
    frf_model: str
    amplifier_gain_db: float
    shaker_accel_m_s2_per_v: float
    shaker_suspension_hz: float
    shaker_suspension_damping_ratio: float
    generator_source_ohm: float
    vibrometer_full_scale_v: float
    noise_v_rms: float
    noise_mm_s_rms: float
    scope_channels: dict[str, str]
    robot: dict[str, Json] | None


class Bench(Protocol):
    """What the control channel may do to the lab (the lab implements it; no import of the lab here)."""

    camera_fps: float
    last_recording: Recording | None
    recordings_dir: Path

    @property
    def spot(self) -> str: ...

    @property
    def setup(self) -> str: ...

    @property
    def truth(self) -> LabTruth: ...

    def set_spot(self, spot: str) -> None: ...

    def set_setup(self, setup: str) -> None: ...

    def inject_fault(self, instrument: str, kind: str = "drop", after: int = 0, match: str | None = None,
                     count: int = 1) -> Any: ...

    def clear_faults(self, instrument: str | None = None) -> None: ...

    def output_state(self, instrument: str = "funcgen", channel: int = 1) -> bool: ...

    def record_video(self, path: str | Path, duration_s: float) -> dict[str, Json]: ...


def _unquote(text: str) -> str:
    text = text.strip()
    if len(text) >= 2 and text[0] == text[-1] and text[0] in "\"'":
        return text[1:-1]
    return text


#: the most frames one clip may hold (10 min at 30 fps; 640 x 480 frames)
MAX_FRAMES = 20_000


def _plain_name(name: str) -> bool:
    """A file name without a directory part (no ``/``, ``\\``, ``..``, nor a leading dot)."""
    return bool(name) and "/" not in name and "\\" not in name and not name.startswith(".") and len(name) <= 200


class SimLabControl(SimScpiInstrument):
    name = "control"
    idn = f"labkit,VirtualLab control,0,{__version__}"

    def __init__(self, lab: Bench) -> None:
        self.lab = lab
        super().__init__()

    def build(self) -> None:
        self.add("LAB:SPOT", set=self._spot, query=lambda c: self.lab.spot.upper())
        self.add("LAB:SETup", set=self._setup, query=lambda c: self.lab.setup.upper())
        self.add("LAB:FAULT", set=self._fault)
        self.add("LAB:FAULT:CLEar", set=lambda c: self.lab.clear_faults(
            c.params[0].lower() if c.params else None))
        self.add("LAB:TRUTh", query=lambda c: json.dumps(to_jsonable(self.lab.truth, finite=True)))
        self.add("LAB:OUTPut", query=self._output)
        self.add("CAM:FPS", set=lambda c: setattr(self.lab, "camera_fps", self.num(c.one(), "", 1.0, 1000.0)),
                 query=lambda c: fmt_num(self.lab.camera_fps))
        self.add("CAM:RECord", set=self._record, query=self._record, answers=True)
        self.add("CAM:DIRectory", query=lambda c: '"' + str(self.lab.recordings_dir) + '"')
        self._filming = threading.Lock()
        self.add("CAM:TIMEstamps", query=self._timestamps)

    def _spot(self, c: Call) -> None:
        try:
            self.lab.set_spot(c.one().lower())
        except ValueError:
            raise ScpiError(-224, "Illegal parameter value;spot is BODY, HIP, KNEE or TRAY") from None

    def _setup(self, c: Call) -> None:
        word = c.one().strip().upper()
        setup = "inchip" if word in ("INCH", "INCHIP") else "shaker" if word in ("SHAK", "SHAKER") else None
        if setup is None:
            raise ScpiError(-224, "Illegal parameter value;setup is INCHIP or SHAKER")
        self.lab.set_setup(setup)

    def _fault(self, c: Call) -> None:
        p = c.params
        if len(p) < 2:
            raise ScpiError(-109)
        if len(p) > 5:
            raise ScpiError(-108)
        try:
            after = int(self.num(p[2], "", 0, 1e9)) if len(p) > 2 else 0
            match = _unquote(p[3]) or None if len(p) > 3 else None
            count = int(self.num(p[4], "", 1, 1e9)) if len(p) > 4 else 1
            self.lab.inject_fault(p[0].strip().lower(), p[1].strip().lower(), after, match, count)
        except ValueError as exc:
            raise ScpiError(-224, f"Illegal parameter value;{exc}") from None

    def _output(self, c: Call) -> str:
        if len(c.params) != 2:
            raise ScpiError(-109)
        inst = c.params[0].strip().lower()
        ch = int(self.num(c.params[1], "", 1, 4))
        return "1" if self.lab.output_state(inst, ch) else "0"

    def _record(self, c: Call) -> str:
        """``CAM:REC "<file name>",<s>``: a clip into the lab's recording folder only (``CAM:DIR?``),
        at most :data:`MAX_FRAMES` frames; filmed with the channel's lock released, so the other
        control commands go on meanwhile. Answers the frame count (0: failed, the reason queued)."""
        if len(c.params) != 2:
            raise ScpiError(-109)
        name = _unquote(c.params[0])
        duration = self.num(c.params[1], "S", 0.05, 600.0)
        folder = Path(self.lab.recordings_dir)
        if not _plain_name(name):
            self.push_error(-224, "Illegal parameter value;camera: a file name only, written to CAM:DIR?")
            return "0"
        if duration * self.lab.camera_fps > MAX_FRAMES:
            self.push_error(-222, f"Data out of range;camera: more than {MAX_FRAMES} frames")
            return "0"
        if not self._filming.acquire(blocking=False):
            self.push_error(-221, "Settings conflict;camera: already recording")
            return "0"
        self.lock.release()
        try:
            info = self.lab.record_video(folder / name, duration)
        except (OSError, ValueError) as exc:
            info = {"frames": 0, "error": str(exc)}
        finally:
            self.lock.acquire()
            self._filming.release()
        if "error" in info:
            # always answer (a client waits for the frame count): 0 frames, and the reason queued
            self.push_error(-230, f"Data corrupt or stale;camera: {info['error']}"[:200])
            return "0"
        return str(info["frames"])

    def _timestamps(self, c: Call) -> str:
        rec = self.lab.last_recording
        if rec is None:
            return ""
        return ",".join(f"{t:.6f}" for t in rec.timestamps_s)
