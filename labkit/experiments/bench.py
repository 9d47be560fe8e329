"""The bench before a run: ``labkit init`` (a commented config) and ``labkit check`` (wiring and loopback).

:func:`run_check` opens the config's instruments (locked, as a run would), and
at a drive that cannot hurt the robot (the config's drive scaled down to at
most :data:`CHECK_VPP`; on the shaker, ``tray_control.start_vpp``) checks, one
:class:`CheckLine` each (PASS / WARN / FAIL, what was measured, what was
expected, what to do):

* identities: each instrument answers as the config's driver expects;
* the vibrometer's range is the config's (set, and read back), its noise floor
  with the drive off, and its over-range state at the check drive;
* the generator's SYNC output and the scope's trigger (source, sweep mode
  NORM) are set, and a triggered acquisition happens;
* the drive channel sees the commanded frequency, amplitude and phase within
  :data:`TOLERANCES` (and the velocity channel does not: that is a swap);
* on the shaker, the tray's velocity against the declared amplifier gain and
  shaker sensitivity;
* the output is off at the end (read back from the generator), on every exit path.
"""
from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple, TypedDict

import numpy as np

from labkit.errors import ConfigError, InputError, InstrumentError, LabkitError
from labkit.experiments import kinds
from labkit.experiments.config import VIB_OUTPUT_MAX_V, InstrumentSpec
from labkit.experiments.kinds import Config
from labkit.jsonutil import Json

if TYPE_CHECKING:  # pragma: no cover - typing only
    from labkit.experiments.protocols import FunctionGenerator, Scope, Vibrometer

#: the largest peak-to-peak drive the check puts out (in-chip: the config's drive scaled down to it)
CHECK_VPP = 1.0
#: what the drive channel must read, relative to what was commanded (scope DC gain +-3 %, generator
#: amplitude +-1 %, and the fit), and the phase at the trigger (SYNC delay and trigger jitter)
TOLERANCES = {"amplitude_rel": 0.05, "frequency_rel": 1e-3, "phase_deg": 10.0}
#: the vibrometer's noise floor with the drive off must stay below this fraction of its full scale
NOISE_FRACTION = 1e-3
#: the tray's velocity against the declared chain: within this factor (20 dB off is a factor of 10)
GAIN_FACTOR = 1.5
PASS, WARN, FAIL = "PASS", "WARN", "FAIL"


class CheckFailed(LabkitError):
    """At least one check FAILed (exit 1): the lines say which and what to do."""

    exit_code = 1


@dataclass
class CheckLine:
    """One check's verdict."""

    name: str
    status: str
    measured: str
    expected: str = ""
    todo: str = ""

    def text(self) -> str:
        line = f"{self.status}  {self.name}: {self.measured}"
        if self.expected:
            line += f" (expected {self.expected})"
        if self.todo and self.status != PASS:
            line += f"\n      -> {self.todo}"
        return line


@dataclass
class CheckReport:
    config: str
    kind: str
    lines: list[CheckLine] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not any(line.status == FAIL for line in self.lines)

    def add(self, name: str, status: str, measured: str, expected: str = "", todo: str = "") -> CheckLine:
        line = CheckLine(name, status, measured, expected, todo)
        self.lines.append(line)
        return line

    def as_dict(self) -> dict[str, Json]:
        """What ``labkit check --json`` prints."""
        return {"config": self.config, "kind": self.kind, "ok": self.ok, "checks": [asdict(x) for x in self.lines]}


# ----------------------------------------------------------------------------- init

def _band(kind: str, start: float | None, stop: float | None, count: int | None) -> Any:
    from labkit.experiments.template import Band

    d = Band() if kind == "inchip" else Band(150.0, 300.0, 3)
    band = Band(d.start_hz if start is None else start, d.stop_hz if stop is None else stop,
                d.count if count is None else count)
    if not (math.isfinite(band.start_hz) and band.start_hz > 0):
        raise InputError(f"{band.start_hz:g} Hz", key="--start-hz", expected="a frequency > 0 Hz")
    if not (math.isfinite(band.stop_hz) and band.stop_hz >= band.start_hz):
        raise InputError(f"{band.stop_hz:g} Hz", key="--stop-hz", expected=f">= --start-hz ({band.start_hz:g} Hz)")
    if not 1 <= band.count <= 100_000:
        raise InputError(f"{band.count}", key="--count", expected="1 to 100000 frequencies")
    return band


class InitSummary(TypedDict):
    """What :func:`init_config` reports (``labkit init --json``): the config written, what is left to
    fill in (``todo``), the next command, the instrument found per role and every identification."""

    config: str
    kind: str
    todo: list[str]
    next: str
    instruments: dict[str, str | None]
    identified: list[dict[str, Json]]


def init_config(out: str | Path, *, kind: str = "inchip", resources: list[str] | tuple[str, ...] = (),
                all_devices: bool = False, lab: bool = False,
                band: tuple[float | None, float | None, int | None] = (None, None, None),
                force: bool = False, timeout_s: float = 0.5) -> InitSummary:
    """Identify the instruments, write a commented config of ``kind`` to ``out``; return a summary.

    Every argument is checked before anything is sent to an instrument.
    """
    from labkit.experiments.discovery import by_role, identify, list_devices
    from labkit.experiments.template import Instrument, Wiring, inchip_text, shaker_text, todo_keys

    path = Path(out)
    if path.exists() and not force:
        raise InputError("already exists; give --force to overwrite it", file=path, key="--out")
    if not path.resolve().parent.is_dir():
        raise InputError("the folder does not exist", file=path, key="--out")
    b = _band(kind, *band)
    res, control = list(resources), None
    if lab:
        from labkit.experiments.locks import served_lab

        rec = served_lab()
        control = rec["resources"].get("control")
        res += [r for role, r in rec["resources"].items() if role != "control"]
    if all_devices:
        res += [r for bk in list_devices().backends if bk.name.startswith(("pyvisa", "pyserial")) for r in bk.resources]
    if not res:
        raise InputError("no instrument to identify", key="RESOURCE", expected="resources, --all or --lab")
    found = [identify(r, timeout_s) for r in dict.fromkeys(res)]
    roles = by_role(found)
    inst = {role: (Instrument(c[0].driver, c[0].resource, c[0].reply) if c else Instrument(None, None))
            for role, c in roles.items()}
    write = inchip_text if kind == "inchip" else shaker_text
    path.write_text(write(inst, Wiring(), control=control, band=b, path=str(path)))
    return {"config": str(path), "kind": kind, "todo": todo_keys(path), "next": f"labkit check {path}",
            "instruments": {role: (f"{c[0].driver} at {c[0].resource}" if c else None) for role, c in roles.items()},
            "identified": [f.as_dict() for f in found]}


# ----------------------------------------------------------------------------- check: set-up

def config_kind(path: str | Path) -> str:
    """``"shaker"`` for a config with an ``[amplifier]`` table, else ``"inchip"``."""
    from labkit.tomlio import load_toml

    data, _ = load_toml(path)
    return "shaker" if "amplifier" in data else "inchip"


def load_checked(path: str | Path, kind: str | None = None) -> Config:
    """The config, validated with every limit; InputError naming the TODOs left, if any."""
    from labkit.experiments.template import todo_keys

    if not Path(path).is_file():
        raise InputError("no such config", file=path)
    left = todo_keys(path)
    if left:
        raise ConfigError(f"still TODO: {', '.join(left)}", file=path, key=left[0],
                          expected="the bench's values in place of every \"TODO\" (see the comments)")
    kind = kind or config_kind(path)
    cfg = kinds.get(kind).load(path)
    kinds.get(kind).preflight(cfg)
    return cfg


def _open(spec: InstrumentSpec, **limits: float) -> Any:
    from labkit.drivers.registry import open_instrument

    settings = dict(spec.settings)
    for k, v in limits.items():
        settings[k] = min(float(settings[k]), v) if isinstance(settings.get(k), (int, float)) else v
    return open_instrument(spec.model, spec.resource, name=spec.role, **settings)


class Opened(NamedTuple):
    """The three instruments ``labkit check`` opened, each past its identity handshake."""

    funcgen: FunctionGenerator
    scope: Scope
    vibrometer: Vibrometer


def _identities(cfg: Config, report: CheckReport, stack: contextlib.ExitStack) -> Opened | None:
    """Open each instrument (its driver's handshake checks the identity); None when one failed."""
    from labkit.experiments.discovery import _hint

    limits = kinds.of(cfg).rig_setup(cfg).funcgen_limits
    opened: dict[str, Any] = {}
    for role in Opened._fields:
        spec = cfg.instruments[role]
        try:
            inst = stack.enter_context(_open(spec, **(limits if role == "funcgen" else {})))
            report.add(f"identity {role}", PASS, inst.identity, f"model {spec.model} at {spec.resource}")
            opened[role] = inst
        except ConfigError as exc:
            report.add(f"identity {role}", FAIL, exc.message, f"model {spec.model}",
                       f"fix instruments.{role}.model (labkit identify {spec.resource})")
        except InstrumentError as exc:
            cause = exc.__cause__ or exc
            report.add(f"identity {role}", FAIL, f"no answer from {spec.resource}: {exc}", f"model {spec.model}",
                       _hint(spec.resource, cause) or f"check instruments.{role}.resource (labkit devices)")
        if role == "scope" and role in opened:   # EXT on a scope without it: ConfigError, nothing set
            opened[role].trigger_source_for(cfg.scope.trigger_source, cfg.scope.drive_channel)
    return Opened(**opened) if len(opened) == len(Opened._fields) else None


# ----------------------------------------------------------------------------- check: measuring

@dataclass
class Sine:
    """A least-squares sine ``amp sin(2 pi f t + phase) + mean`` of a record, and its frequency."""

    amp_vpp: float
    phase_deg: float
    freq_hz: float
    residual_rms: float


def fit_sine(t: np.ndarray, v: np.ndarray, freq_hz: float) -> Sine:
    """Fit at ``freq_hz``; the frequency is refined from the phase drift between the record's halves."""
    def one(tt: np.ndarray, vv: np.ndarray) -> tuple[float, float, np.ndarray]:
        w = 2 * np.pi * freq_hz
        m = np.column_stack([np.sin(w * tt), np.cos(w * tt), np.ones_like(tt)])
        coef, *_ = np.linalg.lstsq(m, vv, rcond=None)
        return float(np.hypot(coef[0], coef[1])), float(np.arctan2(coef[1], coef[0])), vv - m @ coef

    amp, ph, res = one(t, v)
    half = len(t) // 2
    _, p1, _ = one(t[:half], v[:half])
    _, p2, _ = one(t[half:], v[half:])
    dt = float(np.mean(t[half:]) - np.mean(t[:half]))
    dphi = (p2 - p1 + np.pi) % (2 * np.pi) - np.pi
    return Sine(2 * amp, math.degrees(ph), freq_hz + dphi / (2 * np.pi * dt), float(np.std(res)))


def _acquire(scope: Any, channels: tuple[int, ...], record_s: float, timeout_s: float) -> dict[int, Any]:
    scope.single()
    time.sleep(record_s)
    scope.wait_done(timeout_s)
    return {ch: scope.read_waveform(ch) for ch in channels}


def _sweep_mode(scope: Any, mode: str) -> None:
    """``:TRIGger:SWEep AUTO|NORMal`` (both supported scopes), through the driver's generic write."""
    scope.write(f":TRIG:SWE {mode}")
    scope.check_errors(after=f":TRIG:SWE {mode}")


@dataclass
class Bench:
    """What the checks share: the config, the open instruments, the check drive."""

    cfg: Config
    fg: Any
    scope: Any
    vib: Any
    report: CheckReport
    freq_hz: float
    amp_vpp: float
    offset_v: float
    scale: float = 0.0
    mover: Callable[[str], None] | None = None

    @property
    def drive_ch(self) -> int:
        return self.cfg.scope.drive_channel

    @property
    def vel_ch(self) -> int:
        return self.cfg.scope.velocity_channel

    @property
    def trigger(self) -> str:
        """The trigger source: the configured one, or EXT where the scope has it, else the drive."""
        return str(self.scope.trigger_source_for(self.cfg.scope.trigger_source, self.drive_ch))


def _check_range(b: Bench) -> None:
    want = float(b.cfg.scale_mm_s_per_v)
    was = float(b.vib.scale_mm_s_per_v)
    try:
        b.vib.scale_mm_s_per_v = want
        b.scale = want
        b.report.add("vibrometer range", PASS, f"{want:g} mm/s/V" + (f" (was {was:g}, set)" if was != want else ""),
                     f"{want:g} mm/s/V (vibrometer.scale_mm_s_per_v)")
    except InstrumentError as exc:
        b.scale = float(b.vib.scale_mm_s_per_v)
        b.report.add("vibrometer range", FAIL, f"the decoder stays at {b.scale:g} mm/s/V ({exc.args[0]})",
                     f"{want:g} mm/s/V (vibrometer.scale_mm_s_per_v)",
                     "set the range at the controller (is it in local / front-panel mode?), or set "
                     f"vibrometer.scale_mm_s_per_v = {b.scale:g}; velocities would be wrong by "
                     f"x{b.scale / want:g}")


def _check_noise(b: Bench) -> None:
    """The velocity channel with the drive off (AUTO sweep: no trigger comes)."""
    b.scope.setup_channel(b.vel_ch, 0.02, 0.0, "DC")
    b.scope.set_timebase(0.02)
    b.scope.set_record_points(2000)
    _sweep_mode(b.scope, "AUTO")
    w = _acquire(b.scope, (b.vel_ch,), 0.02, 3.0)[b.vel_ch]
    rms_mm_s = float(np.std(w.volts)) * b.scale
    full = VIB_OUTPUT_MAX_V * b.scale
    ok = rms_mm_s < NOISE_FRACTION * full
    b.report.add("vibrometer noise floor", PASS if ok else WARN,
                 f"{rms_mm_s:.3g} mm/s rms with the drive off (scope channel {b.vel_ch})",
                 f"< {NOISE_FRACTION * full:.3g} mm/s ({NOISE_FRACTION:.1%} of the {full:g} mm/s range)",
                 "a noisy laser signal: refocus on a retro-reflective spot, check the signal-level bar")


def _set_sync_trigger(b: Bench) -> bool:
    """The generator's SYNC on, the scope triggered by it (NORM: no trigger, no record). True if set."""
    fg, scope, src = b.fg, b.scope, b.trigger
    level = 1.0 if src == "EXT" else b.offset_v if src == f"CHAN{b.drive_ch}" else 0.0
    try:
        fg.enable_sync()                    # each family's sync commands, read back
        scope.set_trigger(src, level, "POS")   # source, slope, level and NORM sweep, read back
    except InstrumentError as exc:
        b.report.add("sync and trigger set", FAIL, str(exc), f"SYNC on, trigger {src}, sweep NORM",
                     "the instruments refused the settings: see their error queues")
        return False
    # both calls read their settings back and raise on a mismatch: here they hold
    b.report.add("sync and trigger set", PASS, f"generator sync on; scope trigger {src}, sweep NORM (read back)",
                 f"SYNC on, trigger {src}, sweep NORM", "")
    return True


def _drive_on(b: Bench, guard: Any) -> None:
    """A continuous sine: a run may have left the generator in triggered-burst or sweep mode."""
    b.fg.burst_off()
    b.fg.sweep_off()
    b.fg.set_sine(b.freq_hz, b.amp_vpp, b.offset_v)
    guard.on()


def _record(b: Bench, record_s: float, wait_s: float) -> dict[int, Any]:
    """Both channels; a small response narrows the velocity channel (an 8-bit scope would lose it)."""
    out = _acquire(b.scope, (b.drive_ch, b.vel_ch), record_s, wait_s)
    vpd = 2 * VIB_OUTPUT_MAX_V / 8
    for _ in range(3):
        v = np.asarray(out[b.vel_ch].volts)
        peak = float(np.max(np.abs(v - np.mean(v))))
        if peak >= 0.2 * 4 * vpd or vpd <= 0.002:
            break
        vpd = max(peak * 2.5 / 4, 0.002)          # the peak at 40 % of the half screen
        b.scope.setup_channel(b.vel_ch, vpd, 0.0, "DC")
        out = _acquire(b.scope, (b.drive_ch, b.vel_ch), record_s, wait_s)
    return out


def _triggered_record(b: Bench) -> dict[int, Any] | None:
    """A record of both channels triggered by the configured source; None (and a FAIL) if none came."""
    periods = 20
    rec = periods / b.freq_hz
    scope = b.scope
    scope.setup_channel(b.drive_ch, max(b.amp_vpp * 1.25 / 8, 1e-3), b.offset_v, "DC")
    scope.setup_channel(b.vel_ch, 2 * VIB_OUTPUT_MAX_V / 8, 0.0, "DC")
    scope.set_timebase(rec)
    scope.set_trigger_at_start(rec)
    scope.set_record_points(4000)
    wait = max(1.0, 10 * rec)
    t0 = time.monotonic()
    src = b.trigger
    try:
        out = _record(b, rec, wait)
    except InstrumentError:
        b.report.add("triggered acquisition", FAIL, f"no trigger within {wait:g} s with the drive on",
                     f"a trigger from {'the generator SYNC on EXT TRIG' if src == 'EXT' else src}",
                     "is the generator's SYNC output cabled to the scope's EXT TRIG input?" if src == "EXT"
                     else f"is the drive on scope channel {src[4:]}?")
        return None
    b.report.add("triggered acquisition", PASS, f"triggered and recorded in {time.monotonic() - t0:.2f} s",
                 f"a trigger from {src}")
    return out


def _check_drive(b: Bench, rec: dict[int, Any], triggered: bool) -> None:
    wd, wv = rec[b.drive_ch], rec[b.vel_ch]
    d = fit_sine(np.asarray(wd.t_s), np.asarray(wd.volts), b.freq_hz)
    v = fit_sine(np.asarray(wv.t_s), np.asarray(wv.volts), b.freq_hz)
    tol = TOLERANCES
    swapped = abs(v.amp_vpp / b.amp_vpp - 1) < tol["amplitude_rel"] and abs(d.amp_vpp / b.amp_vpp - 1) > 0.5
    amp_ok = abs(d.amp_vpp / b.amp_vpp - 1) <= tol["amplitude_rel"]
    todo = (f"the drive is on scope channel {b.vel_ch}: the channels are swapped (swap the cables, or "
            f"scope.drive_channel = {b.vel_ch}, scope.velocity_channel = {b.drive_ch})" if swapped
            else "a factor 2: the generator's load setting (high-Z expected); else the cable or the channel")
    b.report.add(f"drive amplitude (scope channel {b.drive_ch})", PASS if amp_ok else FAIL,
                 f"{d.amp_vpp:.4g} Vpp", f"{b.amp_vpp:.4g} Vpp +-{tol['amplitude_rel']:.0%}", todo)
    f_ok = amp_ok and abs(d.freq_hz / b.freq_hz - 1) <= tol["frequency_rel"]
    b.report.add("drive frequency", PASS if f_ok else FAIL, f"{d.freq_hz:.6g} Hz",
                 f"{b.freq_hz:.6g} Hz +-{tol['frequency_rel']:.1%}",
                 todo if not amp_ok else "the scope's time base or the generator's clock")
    if not triggered:
        b.report.add("drive phase at the trigger", FAIL, "not measured: no trigger", "a triggered record",
                     "see 'triggered acquisition'")
    elif b.trigger == "EXT":
        p_ok = amp_ok and abs(d.phase_deg) <= tol["phase_deg"]
        b.report.add("drive phase at the trigger", PASS if p_ok else FAIL, f"{d.phase_deg:+.1f} deg",
                     f"0 deg +-{tol['phase_deg']:g} (SYNC marks the sine's phase zero)",
                     todo if not amp_ok else "the trigger slope/level, or a delayed SYNC")
    if swapped:
        b.report.add(f"velocity channel (scope channel {b.vel_ch})", FAIL,
                     f"carries the drive ({v.amp_vpp:.4g} Vpp, {v.phase_deg:+.1f} deg)",
                     "the vibrometer's output", todo)
        return
    vel = v.amp_vpp / 2 * b.scale
    # the fitted amplitude's standard error is residual_rms * sqrt(2 / N)
    snr = v.amp_vpp / 2 / max(v.residual_rms * math.sqrt(2 / len(wv.volts)), 1e-12)
    b.report.add(f"velocity channel (scope channel {b.vel_ch})", PASS if snr >= 10 else WARN,
                 f"{vel:.3g} mm/s peak at {b.freq_hz:g} Hz, {snr:.3g} x its standard error",
                 "a sine at the drive frequency, >= 10 x its standard error",
                 "no response at the check drive: is the laser on the robot (or tray)?")


def _check_over_range(b: Bench) -> None:
    over = b.vib.over_range()
    b.report.add("vibrometer over-range", FAIL if over else PASS,
                 "OVER RANGE at the check drive" if over else "not over range at the check drive",
                 "not over range", f"a larger range (vibrometer.scale_mm_s_per_v > {b.scale:g} mm/s/V)")


def _check_gain(b: Bench, rec: dict[int, Any]) -> None:
    """Shaker: the tray's velocity (laser on the tray) against the declared gain and sensitivity."""
    from labkit.experiments.config import ShakerConfig

    cfg = b.cfg
    assert isinstance(cfg, ShakerConfig)
    accel = cfg.accel_m_s2_per_v
    if accel is None:
        b.report.add("amplifier gain", WARN, "not checked: the shaker's sensitivity is not declared",
                     "shaker.accel_m_s2_per_v", "declare shaker.accel_m_s2_per_v (m/s^2 per V at the amplifier "
                     "output) so the gain can be checked")
        return
    amp, _ = kinds.shaker_chain(cfg)
    v = fit_sine(np.asarray(rec[b.vel_ch].t_s), np.asarray(rec[b.vel_ch].volts), b.freq_hz)
    meas = v.amp_vpp / 2 * b.scale
    pred = accel * amp.voltage_gain * b.amp_vpp / 2 / (2 * math.pi * b.freq_hz) * 1e3
    ratio = meas / pred if pred > 0 else float("nan")
    ok = 1 / GAIN_FACTOR <= ratio <= GAIN_FACTOR
    b.report.add("amplifier gain", PASS if ok else FAIL,
                 f"tray {meas:.3g} mm/s peak at {b.amp_vpp:g} Vpp, {b.freq_hz:g} Hz: {20 * math.log10(ratio):+.1f} dB "
                 "from the declared chain" if ratio > 0 else "no tray motion",
                 f"{pred:.3g} mm/s (amplifier.gain_db = {cfg.gain_db:g} dB, attenuator {cfg.attenuator_db:g} dB, "
                 f"{accel:g} m/s^2/V) within x{GAIN_FACTOR:g}",
                 f"is the amplifier's gain switch at {cfg.gain_db:g} dB (and its attenuator at "
                 f"{cfg.attenuator_db:g} dB)? A {20 * math.log10(ratio) if ratio > 0 else 0:+.0f} dB error "
                 "changes every drive")


def _check_off(b: Bench, guard: Any) -> None:
    guard.final_off("check done")
    on = b.fg.output_on
    b.report.add("output off", FAIL if on else PASS, f"{b.fg._outp('?')} -> {'on' if on else 'off'}", "off",
                 "turn the generator output off by hand (labkit off CONFIG)")


# ----------------------------------------------------------------------------- check: the whole

def _check_drive_levels(cfg: Config) -> tuple[float, float, float]:
    """(frequency, Vpp, offset) of the check drive: small, inside the config's band."""
    freqs = sorted(cfg.freqs_hz)
    f = float(freqs[len(freqs) // 2])
    if cfg.kind == "shaker":
        return f, float(cfg.control.start_vpp), 0.0      # type: ignore[union-attr]
    k = min(1.0, CHECK_VPP / cfg.amp_vpp)                  # type: ignore[union-attr]
    return f, cfg.amp_vpp * k, cfg.offset_v * k            # type: ignore[union-attr]


def _mover(cfg: Config, stack: contextlib.ExitStack) -> Callable[[str], None]:
    from labkit.experiments.rig import LabSpot, PromptSpot

    if "control" in cfg.instruments:
        from labkit.lab.client import LabControl

        ctl = stack.enter_context(LabControl(cfg.instruments["control"].resource))
        ctl.set_setup(kinds.of(cfg).lab_setup)
        return LabSpot(ctl).move
    return PromptSpot().move


def run_check(config: str | Path, *, lab: Any = False) -> CheckReport:
    """Check the wiring of ``config``'s rig (see the module docstring); the report's ``ok`` is False on a FAIL.

    ``lab``: False (the config's instruments), True (a virtual lab in-process), ``"served"``
    (the running ``labkit lab serve``, else as True), or a :class:`labkit.lab.VirtualLab`.
    """
    from labkit.experiments.safety import DriveGuard, signals_raise

    cfg = load_checked(config)
    report = CheckReport(str(config), cfg.kind)
    with signals_raise(), contextlib.ExitStack() as stack:
        if lab is not False:
            from labkit.experiments.session import served_or_new, virtual_lab

            obj = served_or_new() if lab == "served" else lab
            _, cfg = stack.enter_context(virtual_lab(cfg, lab=None if obj is True else obj))
        from labkit.experiments.locks import lock_instruments

        # the instruments locked as a run locks them: a run in progress is never disturbed
        stack.enter_context(lock_instruments(((r, sp.resource) for r, sp in cfg.instruments.items()), str(cfg.path)))
        opened = _identities(cfg, report, stack)
        if opened is None:
            report.add("wiring", FAIL, "not checked: an instrument did not identify", "",
                       "fix the identities first")
            return report
        f, vpp, off = _check_drive_levels(cfg)
        b = Bench(cfg, opened.funcgen, opened.scope, opened.vibrometer, report, f, vpp, off,
                  mover=_mover(cfg, stack))
        guard = DriveGuard(b.fg, where=f"{cfg.instruments['funcgen'].model} at {cfg.instruments['funcgen'].resource}",
                           config=str(cfg.path))
        try:
            b.fg.safe_off()
            b.fg.set_load_high_z()
            _run_checks(b, guard)
        finally:
            _check_off(b, guard)
    return report


def _run_checks(b: Bench, guard: Any) -> None:
    assert b.mover is not None
    b.mover("tray" if b.cfg.kind == "shaker" else b.cfg.locations[0])   # type: ignore[union-attr]
    _check_range(b)
    _check_noise(b)
    if not _set_sync_trigger(b):
        return
    _drive_on(b, guard)
    rec = _triggered_record(b)
    triggered = rec is not None
    if rec is None:
        _sweep_mode(b.scope, "AUTO")        # still look at the channels (no phase without a trigger)
        rec = _record(b, 20 / b.freq_hz, 3.0)
    _check_drive(b, rec, triggered)
    _check_over_range(b)
    if b.cfg.kind == "shaker":
        _check_gain(b, rec)
    guard.off("check measured")
    _sweep_mode(b.scope, "NORM")
