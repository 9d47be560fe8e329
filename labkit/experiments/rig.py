"""The rig: the open instruments of one experiment, set up from a validated config.

Only the runner uses a rig. Limits are handed to the drivers so they are
checked before anything is sent: the PZT voltage limit becomes the
generator's ``max_v`` in-chip; the amplifier's input cap for its declared gain
becomes the generator's ``max_amp_vpp`` on the shaker.

The laser spot is moved by a :class:`LabSpot` (the virtual lab's control
channel) or a :class:`PromptSpot` (asks the person at the terminal).
"""
from __future__ import annotations

import math
import sys
from typing import Any, Callable, TextIO

from labkit.errors import InputError, InstrumentError, LimitError
from labkit.experiments.config import VIB_OUTPUT_MAX_V, InchipConfig, InstrumentSpec, ShakerConfig
from labkit.experiments.safety import Interlock

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

    def __init__(self, control: Any) -> None:
        self.control = control

    def move(self, spot: str) -> None:
        self.control.set_spot(spot)


def _open(spec: InstrumentSpec, **extra: Any) -> Any:
    from drivers.registry import open_instrument

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
    except InputError as exc:
        raise type(exc)(exc.message, file=exc.file, key=f"instruments.{spec.role}." + (exc.key or "model"),
                        expected=exc.expected) if not isinstance(exc, LimitError) else exc
    return inst


class Rig:
    """Open instruments for one run (use as a context manager: everything is closed at exit)."""

    def __init__(self, cfg: InchipConfig | ShakerConfig, *, spot: Any | None = None) -> None:
        self.cfg = cfg
        self.funcgen: Any = None
        self.scope: Any = None
        self.vibrometer: Any = None
        self.control: Any = None
        self.camera: Any = None
        self.amplifier: Any = None
        self.envelope: Any = None
        self.drive_channel = cfg.scope.drive_channel
        self.velocity_channel = cfg.scope.velocity_channel
        self.scale_mm_s_per_v = cfg.scale_mm_s_per_v
        self._spot = spot
        self._funcgen_limits: dict[str, Any] = {}
        self.velocity_vpd = cfg.scope.velocity_volts_per_div or 2 * VIB_OUTPUT_MAX_V / VERTICAL_DIVS
        self.drive_vpd: float | None = None
        self._at: str | None = None                  # where the laser points
        self._range_at: dict[str, float] = {}        # velocity V/div last used per spot

    # -- opening ---------------------------------------------------------------------------
    def open(self) -> "Rig":
        cfg = self.cfg
        inst = cfg.instruments
        try:
            if "control" in inst:
                from labkit.lab.client import LabControl

                self.control = LabControl(inst["control"].resource)
                self.control.set_setup("inchip" if cfg.kind == "inchip" else "shaker")
            if isinstance(cfg, ShakerConfig):
                from drivers.shaker import Amplifier2718, Shaker4809Envelope

                self.amplifier = Amplifier2718(gain_db=cfg.gain_db, attenuator_db=cfg.attenuator_db,
                                               current_limit_a=cfg.current_limit_a,
                                               max_input_vrms=cfg.max_input_vrms)
                self.max_drive_vpp = float(self.amplifier.max_input_vpp)
                self.envelope = Shaker4809Envelope(**cfg.envelope)
                self._funcgen_limits = {"max_amp_vpp": self.max_drive_vpp, "max_v": self.max_drive_vpp / 2}
            else:
                self._funcgen_limits = {"max_v": min(cfg.pzt_max_v, 10.0)}
            self.funcgen = _open(inst["funcgen"], **self._funcgen_limits)
            # A generator may come up with its output on from an earlier session: off first.
            self.funcgen.safe_off()
            self.funcgen.set_load_high_z()
            self.scope = _open(inst["scope"])
            self.scope.poll_s = 0.002       # completion polls: fine-grained (the record time is slept)
            self.vibrometer = _open(inst["vibrometer"])
            self.vibrometer.scale_mm_s_per_v = cfg.scale_mm_s_per_v
            self.scale_mm_s_per_v = float(self.vibrometer.scale_mm_s_per_v)
            self.scope.setup_channel(self.velocity_channel, self.velocity_vpd, 0.0, "DC")
            trig = cfg.scope.trigger_source
            # EXT: the generator's TTL sync (phase zero of the sine, start of a sweep)
            level = 1.0 if trig == "EXT" else (getattr(cfg, "offset_v", 0.0) if trig == f"CHAN{self.drive_channel}"
                                               else 0.0)
            self.scope.set_trigger(trig, level, "POS")
            if isinstance(cfg, InchipConfig):
                self.on_drive_amplitude(cfg.amp_vpp, cfg.offset_v)
            if isinstance(cfg, ShakerConfig) and cfg.video_s > 0:
                self.camera = self._open_camera()
            if self._spot is None:
                self._spot = LabSpot(self.control) if self.control is not None else PromptSpot()
        except BaseException:
            self.close()
            raise
        return self

    def _open_camera(self) -> Any:
        spec = self.cfg.instruments.get("camera")
        if spec is None or spec.model == "LabCamera":
            from labkit.lab.client import LabCamera

            resource = spec.resource if spec is not None else self.cfg.instruments["control"].resource
            return LabCamera(resource)
        import drivers.camera as cam

        if spec.model == "OpenCVCamera":
            return cam.OpenCVCamera(**spec.settings)
        if spec.model == "FileCamera":
            return cam.FileCamera(spec.resource or spec.settings.get("path"))
        raise InputError(f"unknown camera model {spec.model!r}", file=self.cfg.path,
                         key="instruments.camera.model", expected="LabCamera, OpenCVCamera or FileCamera")

    def set_record_points(self, points: int) -> None:
        """Points per record (InfiniiVision: ``:WAV:POIN``; sent now so the next record has them)."""
        points = int(max(100, min(points, self.cfg.scope.max_points)))
        if getattr(self, "_points", None) == points:
            return
        if hasattr(self.scope, "points"):
            self.scope.points = points
            self.scope.write(":WAV:POIN:MODE RAW")
            self.scope.write(f":WAV:POIN {points}")
        self._points = points

    def chirp_timebase(self, length_s: float) -> None:
        """Record exactly the sweep: the trigger (sweep start) at the record's first sample.

        InfiniiVision: reference LEFT puts the trigger one division (10 %) in;
        a delay of that much moves it to the record's start.
        """
        self.scope.set_timebase(length_s)
        if hasattr(self.scope, "points"):
            self.scope.write(":TIM:REF LEFT")
            self.scope.write(f":TIM:POS {0.1 * length_s:.6g}")

    def reopen_funcgen(self) -> Any:
        """A new connection to the generator (the old link was lost)."""
        self.funcgen = _open(self.cfg.instruments["funcgen"], **self._funcgen_limits)
        return self.funcgen

    def close(self) -> None:
        for name in ("camera", "vibrometer", "scope", "control", "funcgen"):
            obj = getattr(self, name)
            if obj is None:
                continue
            try:
                obj.close()
            except Exception:
                pass

    def __enter__(self) -> "Rig":
        return self.open()

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # -- what the runner asks --------------------------------------------------------------
    def move_spot(self, spot: str) -> None:
        """Move the laser; the velocity channel gets back the range it last had at that spot."""
        if self._at is not None:
            self._range_at[self._at] = self.velocity_vpd
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
        cap = getattr(self, "max_drive_vpp", None)
        if cap is not None and vpp > cap:
            raise Interlock(f"drive {vpp:.4g} Vpp needed exceeds the amplifier input cap {cap:.4g} Vpp "
                            f"at {self.cfg.gain_db:g} dB gain")

    def check_envelope(self, freq_hz: float, disp_amp_um: float) -> None:
        """Interlock when the shaker's stroke/velocity/force/frequency envelope would be exceeded."""
        if self.envelope is None:
            return
        try:
            self.envelope.check(freq_hz, disp_amp_um, payload_kg=self.cfg.payload_kg)
        except LimitError as exc:
            raise Interlock(f"shaker envelope: {exc.message}") from None

    def record_video(self, path: Any, duration_s: float) -> dict[str, Any]:
        if self.camera is None:
            raise InstrumentError("no camera", instrument="camera", command="record")
        return self.camera.record(str(path), duration_s)

    def snapshots(self) -> dict[str, tuple[str, str, dict[str, Any]]]:
        """role -> (model, resource, snapshot) for the run file."""
        out = {}
        for role in ("funcgen", "scope", "vibrometer"):
            obj = getattr(self, role)
            spec = self.cfg.instruments[role]
            out[role] = (spec.model, spec.resource, obj.snapshot())
        if self.control is not None:
            spec = self.cfg.instruments["control"]
            out["control"] = (spec.model, spec.resource, {"resource": spec.resource})
        if self.amplifier is not None:
            out["amplifier"] = ("2718 (declared)", "", _declared(self.amplifier) | {
                "max_drive_vpp": self.max_drive_vpp})
            out["shaker"] = ("4809 (declared)", "", _declared(self.envelope) | {"payload_kg": self.cfg.payload_kg})
        if self.camera is not None:
            spec = self.cfg.instruments.get("camera")
            snap = self.camera.snapshot() if hasattr(self.camera, "snapshot") else {"type": type(self.camera).__name__}
            out["camera"] = (spec.model if spec else "LabCamera", spec.resource if spec else "", snap)
        return out


def _declared(obj: Any) -> dict[str, Any]:
    if hasattr(obj, "snapshot"):
        return obj.snapshot()
    import dataclasses

    if dataclasses.is_dataclass(obj):
        return dataclasses.asdict(obj)
    return {k: v for k, v in vars(obj).items() if not k.startswith("_")}
