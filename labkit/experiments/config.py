"""Experiment configs (TOML): the in-chip swept-sine test and the out-of-chip shaker run.

Both are validated completely before any instrument is opened; every error is
a :class:`labkit.errors.ConfigError` naming the file, the key and what was
expected (CLI exit 2). See ``sample_data/inchip.toml`` and
``sample_data/shaker.toml`` for annotated examples.

Common tables
-------------
``[instruments.<role>]``
    ``model`` (a driver name, see :mod:`labkit.drivers.registry`), ``resource`` (a VISA
    resource string or device path); any other key is a driver setting
    (``channel``, ``timeout_s`` ...). Roles: ``funcgen``, ``scope``,
    ``vibrometer``, optional ``control`` (a virtual-lab control channel: the run
    then moves the laser spot itself instead of asking the person), and for
    shaker runs ``camera``.
``[scope]``
    ``drive_channel``, ``velocity_channel`` (1-4), optional
    ``drive_volts_per_div`` / ``velocity_volts_per_div`` (else chosen from
    the drive amplitude and the vibrometer's analog range).
``[vibrometer]``
    ``scale_mm_s_per_v`` (the velocity decoder range).
``[method]``
    ``kind = "stepped"``: ``settle_s`` or ``settle_cycles`` (one of them),
    ``dwell_cycles``, ``keep_raw``; ``kind = "chirp"`` (in-chip only):
    ``length_s``, ``averages``.
``[run]``
    ``on_interlock = "skip" | "end"``.

Limits (checked here, before anything is opened; the message names file and key)
-------------------------------------------------------------------------------
Every number must be finite. Declared limits may be lowered, never raised above
the published ones: ``drive.pzt_max_v`` <= 20 V (the thin-film PZT), the drive
peak <= 10 V (the generators' range into high-Z), frequencies <= the
generator family's maximum (20 MHz, DG1000Z 25 MHz), ``amplifier.max_input_vrms``
<= 0.8 V rms at 20 dB (0.08 at 40 dB), the 4809 envelope in ``[shaker]``
(``freq_min_hz`` >= 10 Hz, ``freq_max_hz`` <= 20 kHz, ``force_peak_n`` <= 44.5 N,
``stroke_peak_mm`` <= 4 mm, ``velocity_peak_m_s`` <= 1.65 m/s,
``moving_mass_kg`` >= 0.060 kg), ``interlock.tray_max_um`` <= 4000 um.
``[shaker] accel_m_s2_per_v`` (optional): the tray's acceleration per volt at
the amplifier's output; with it, a ``drive_vpp`` grid's tray travel is predicted
and checked before anything is sent (else each point ramps up from
``tray_control.start_vpp`` while the tray is measured: a soft start).
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from labkit.experiments.tomlcheck import Table
from labkit.jsonutil import Json
from labkit.tomlio import TomlValue, load_toml

LOCATIONS = ("body", "hip", "knee")
SPOTS = ("body", "hip", "knee", "tray")
ON_INTERLOCK = ("skip", "end")
DEFAULT_PZT_MAX_V = 20.0
#: overridable fields of the shaker envelope (labkit.drivers.shaker.Shaker4809Envelope)
ENVELOPE_KEYS = ("freq_min_hz", "freq_max_hz", "force_peak_n", "stroke_peak_mm", "velocity_peak_m_s",
                 "moving_mass_kg")
# Analog output of the vibrometer controllers spans +-10 V (OFV-3001/5000 manuals).
VIB_OUTPUT_MAX_V = 10.0
#: the thin-film PZT's rating (the paper: 5-20 V actuation): drive.pzt_max_v may be lowered, not raised
PZT_RATED_MAX_V = 20.0
#: every supported generator's output range into a high-impedance load: +-10 V
FUNCGEN_MAX_V = 10.0
#: the smallest amplitude every supported generator puts out (the drivers' floor, Vpp)
FUNCGEN_MIN_VPP = 1e-3
#: the longest an instrument link may wait for a reply (the drivers' ceiling, s)
MAX_TIMEOUT_S = 3600.0
#: record points per drive period: more is a typo (the scope's record holds at most 8 M points)
MAX_SAMPLES_PER_CYCLE = 1e5
#: the highest sine frequency of each generator family (the smallest model of the family:
#: 33220A 20 MHz, 33500B 20 MHz (33511B/33521B), DG1000Z 25 MHz (DG1022Z))
FUNCGEN_MAX_HZ = {"33220A": 20e6, "33500B": 20e6, "DG1000Z": 25e6}
#: the longest settling a point may ask for (s); a longer one is a typo, not a measurement
MAX_SETTLE_S = 600.0
#: the 2718's published input cap (V rms) per gain switch position; max_input_vrms may only lower it
AMP_MAX_INPUT_VRMS = {20.0: 0.8, 40.0: 0.08}


@dataclass(frozen=True)
class InstrumentSpec:
    """One instrument: driver model, resource and extra driver settings."""

    role: str
    model: str
    resource: str
    settings: dict[str, Any] = field(default_factory=dict)

    def with_resource(self, resource: str) -> InstrumentSpec:
        return InstrumentSpec(self.role, self.model, resource, dict(self.settings))


@dataclass(frozen=True)
class Method:
    """How each frequency is measured."""

    kind: str                       # "stepped" | "chirp"
    settle_s: float | None = None   # fixed settling time, or ...
    settle_cycles: float | None = None  # ... a number of drive periods
    dwell_cycles: float = 20.0      # periods recorded per point
    keep_raw: bool = False
    length_s: float = 1.0           # chirp length
    averages: int = 1               # chirps averaged into H1

    def settle_time_s(self, freq_hz: float) -> float:
        if self.settle_s is not None:
            return self.settle_s
        return (self.settle_cycles or 0.0) / freq_hz

    def dwell_time_s(self, freq_hz: float) -> float:
        return self.dwell_cycles / freq_hz


@dataclass(frozen=True)
class ScopeSetup:
    drive_channel: int
    velocity_channel: int
    drive_volts_per_div: float | None = None
    velocity_volts_per_div: float | None = None
    trigger_source: str | None = None  # the generator's sync into EXT, or CHAN<n>; None: EXT if the scope has it
    samples_per_cycle: float = 100.0   # record points per drive period (stepped sine)
    max_points: int = 100_000          # cap on record points
    acquisition: str = "normal"        # "normal" | "average" (the scope averages `averages` triggered records)
    averages: int = 1


@dataclass(frozen=True)
class InchipConfig:
    """A validated in-chip sweep config (see module docstring and ``sample_data/inchip.toml``)."""

    path: str
    text: str
    instruments: dict[str, InstrumentSpec]
    amp_vpp: float
    offset_v: float
    pzt_max_v: float
    freqs_hz: tuple[float, ...]
    method: Method
    locations: tuple[str, ...]
    scope: ScopeSetup
    scale_mm_s_per_v: float
    on_interlock: str

    kind = "inchip"

    def with_resources(self, resources: dict[str, str]) -> InchipConfig:
        return _with_resources(self, resources)


@dataclass(frozen=True)
class TrayControl:
    """Reaching a tray displacement: iterate the drive until the measured amplitude is close."""

    tolerance: float = 0.02     # relative
    max_iterations: int = 8
    start_vpp: float = 0.05     # first try at a new frequency (small: safe)
    max_step_ratio: float = 4.0  # never raise the drive by more than this per step


@dataclass(frozen=True)
class ShakerConfig:
    """A validated shaker-run config (see ``sample_data/shaker.toml``)."""

    path: str
    text: str
    instruments: dict[str, InstrumentSpec]
    gain_db: float
    attenuator_db: float
    current_limit_a: float
    max_input_vrms: float | None
    payload_kg: float
    envelope: dict[str, float]
    freqs_hz: tuple[float, ...]
    amplitude_kind: str             # "tray_amp_um" | "drive_vpp"
    amplitudes: tuple[float, ...]
    control: TrayControl
    method: Method
    robot_spot: str
    video_s: float
    scope: ScopeSetup
    scale_mm_s_per_v: float
    tray_max_um: float
    on_interlock: str
    #: declared tray acceleration per volt at the amplifier's output (m/s^2/V, with the payload):
    #: when given, every drive_vpp point's tray travel is predicted before anything is sent
    accel_m_s2_per_v: float | None = None

    kind = "shaker"

    def with_resources(self, resources: dict[str, str]) -> ShakerConfig:
        return _with_resources(self, resources)


def _with_resources(cfg: Any, resources: dict[str, str]) -> Any:
    """A copy whose instruments point at ``resources`` (role -> resource); new roles are added."""
    import dataclasses

    inst = dict(cfg.instruments)
    for role, resource in resources.items():
        if role in inst:
            inst[role] = inst[role].with_resource(resource)
    return dataclasses.replace(cfg, instruments=inst)


# ----------------------------------------------------------------------------- loading

def load_inchip(path: str | Path) -> InchipConfig:
    """Read and validate an in-chip sweep config.

    Raises
    ------
    ConfigError
        Naming the file, the key and what was expected.
    """
    data, text = load_toml(path)
    root = Table(data, path)
    root.only(("run", "instruments", "drive", "frequencies", "method", "scope", "vibrometer"))
    instruments = _instruments(root.table("instruments"), required=("funcgen", "scope", "vibrometer"),
                               optional=("control",))
    run = root.table("run", required=False)
    run.only(("locations", "on_interlock"))
    locations = run.strings("locations", choices=LOCATIONS, default=LOCATIONS)
    on_interlock = run.string("on_interlock", choices=ON_INTERLOCK, default="skip", lower=True)

    drive = root.table("drive")
    drive.only(("amp_vpp", "offset_v", "pzt_max_v"))
    pzt_max_v = drive.number("pzt_max_v", default=DEFAULT_PZT_MAX_V, unit="V", minimum=0,
                             exclusive_minimum=True, maximum=PZT_RATED_MAX_V)
    amp_vpp = drive.number("amp_vpp", unit="Vpp", minimum=FUNCGEN_MIN_VPP)
    offset_v = drive.number("offset_v", default=0.0, unit="V")
    peak = abs(offset_v) + amp_vpp / 2
    if peak > pzt_max_v:
        raise drive.error("amp_vpp", f"drive peak |offset_v| + amp_vpp/2 = {peak:g} V exceeds the PZT "
                                     f"limit drive.pzt_max_v = {pzt_max_v:g} V",
                          f"|offset_v| + amp_vpp/2 <= {pzt_max_v:g} V")
    if peak > FUNCGEN_MAX_V:
        raise drive.error("amp_vpp", f"drive peak |offset_v| + amp_vpp/2 = {peak:g} V is beyond the "
                                     f"generator's output range (+-{FUNCGEN_MAX_V:g} V into high-Z)",
                          f"|offset_v| + amp_vpp/2 <= {FUNCGEN_MAX_V:g} V")

    freqs = _frequencies(root.table("frequencies"))
    _check_generator_band(root, "frequencies", "list_hz" if "list_hz" in root.table("frequencies") else "stop_hz",
                          freqs, instruments)
    method = _method(root.table("method"), allow_chirp=True)
    _check_point_lengths(root.table("method"), method, freqs)
    if method.kind == "chirp":
        f = root.table("frequencies")
        if "list_hz" in f:
            raise f.error("list_hz", "a chirp sweeps a band", "start_hz/stop_hz (and count) for method.kind = 'chirp'")
        span = max(freqs) / min(freqs)
        if span <= 1:
            raise f.error("stop_hz", "empty band", "stop_hz > start_hz for a chirp")
    scope = _scope(root.table("scope"), instruments["scope"].model)
    if method.kind == "chirp" and scope.averages > 1:
        raise root.table("scope").error("acquisition", "'average' with method.kind = 'chirp'",
                                        "'normal' (a chirp's records are averaged by method.averages)")
    vib = root.table("vibrometer")
    vib.only(("scale_mm_s_per_v",))
    scale = vib.number("scale_mm_s_per_v", unit="mm/s/V", minimum=0, exclusive_minimum=True)
    return InchipConfig(str(path), text, instruments, amp_vpp, offset_v, pzt_max_v, freqs, method,
                        locations, scope, scale, on_interlock)


def load_shaker(path: str | Path) -> ShakerConfig:
    """Read and validate a shaker-run config (errors as :func:`load_inchip`)."""
    data, text = load_toml(path)
    root = Table(data, path)
    root.only(("run", "instruments", "amplifier", "shaker", "grid", "tray_control", "method", "scope",
               "vibrometer", "interlock"))
    instruments = _instruments(root.table("instruments"), required=("funcgen", "scope", "vibrometer"),
                               optional=("control", "camera"))
    run = root.table("run", required=False)
    run.only(("robot_spot", "video_s", "on_interlock"))
    robot_spot = run.string("robot_spot", choices=LOCATIONS, default="knee", lower=True)
    video_s = run.number("video_s", default=0.0, unit="s", minimum=0, maximum=MAX_SETTLE_S)
    on_interlock = run.string("on_interlock", choices=ON_INTERLOCK, default="skip", lower=True)
    if video_s > 0 and "camera" not in instruments and "control" not in instruments:
        raise root.table("instruments").error("camera", "run.video_s > 0 needs a camera",
                                              "an [instruments.camera] table (or an [instruments.control] "
                                              "virtual-lab channel)")

    amp = root.table("amplifier")
    amp.only(("model", "gain_db", "attenuator_db", "current_limit_a", "max_input_vrms"))
    gain_db = amp.number("gain_db", unit="dB")
    if gain_db not in (20.0, 40.0):
        raise amp.error("gain_db", f"unsupported gain {gain_db:g} dB", "20 or 40 (the 2718's gain switch)")
    attenuator_db = amp.number("attenuator_db", unit="dB", minimum=0)
    current_limit_a = amp.number("current_limit_a", unit="A", minimum=0, exclusive_minimum=True)
    cap = AMP_MAX_INPUT_VRMS[gain_db]
    max_input_vrms = amp.number("max_input_vrms", default=None, unit="V rms", minimum=0, exclusive_minimum=True,
                                maximum=cap)

    shaker = root.table("shaker", required=False)
    shaker.only(("model", "payload_kg", "accel_m_s2_per_v") + ENVELOPE_KEYS)
    accel = shaker.number("accel_m_s2_per_v", default=None, unit="m/s^2 per V", minimum=0, exclusive_minimum=True)
    payload_kg = shaker.number("payload_kg", default=0.0, unit="kg", minimum=0, maximum=10.0)
    envelope = {k: _envelope_value(shaker, k) for k in ENVELOPE_KEYS if k in shaker}
    if envelope.get("freq_min_hz", 0.0) >= envelope.get("freq_max_hz", float("inf")):
        raise shaker.error("freq_max_hz", "the band is empty", "freq_max_hz > freq_min_hz")

    grid = root.table("grid")
    grid.only(("freq_hz", "tray_amp_um", "drive_vpp"))
    freqs = grid.numbers("freq_hz", unit="Hz", minimum=0, exclusive_minimum=True)
    _check_generator_band(root, "grid", "freq_hz", freqs, instruments)
    if ("tray_amp_um" in grid) == ("drive_vpp" in grid):
        raise grid.error("tray_amp_um", "give the amplitudes one way",
                         "exactly one of grid.tray_amp_um (tray displacement, um) or grid.drive_vpp")
    kind = "tray_amp_um" if "tray_amp_um" in grid else "drive_vpp"
    amps = grid.numbers(kind, unit="um" if kind == "tray_amp_um" else "Vpp",
                        **({"minimum": 0, "exclusive_minimum": True} if kind == "tray_amp_um"
                           else {"minimum": FUNCGEN_MIN_VPP}))

    tc = root.table("tray_control", required=False)
    tc.only(("tolerance", "max_iterations", "start_vpp", "max_step_ratio"))
    control = TrayControl(
        tolerance=tc.number("tolerance", default=0.02, minimum=0, maximum=0.5, exclusive_minimum=True),
        max_iterations=tc.integer("max_iterations", default=8, minimum=1, maximum=50),
        start_vpp=tc.number("start_vpp", default=0.05, unit="Vpp", minimum=FUNCGEN_MIN_VPP,
                            maximum=2 * math.sqrt(2) * (max_input_vrms or cap)),
        max_step_ratio=tc.number("max_step_ratio", default=4.0, minimum=1, exclusive_minimum=True))

    method = _method(root.table("method"), allow_chirp=False)
    _check_point_lengths(root.table("method"), method, freqs, video_s=video_s)
    scope = _scope(root.table("scope"), instruments["scope"].model)
    vib = root.table("vibrometer")
    vib.only(("scale_mm_s_per_v",))
    scale = vib.number("scale_mm_s_per_v", unit="mm/s/V", minimum=0, exclusive_minimum=True)
    il = root.table("interlock")
    il.only(("tray_max_um",))
    stroke_um = 1e3 * _envelope_defaults()["stroke_peak_mm"]   # the 4809 itself (a lowered stroke interlocks)
    tray_max_um = il.number("tray_max_um", unit="um", minimum=0, exclusive_minimum=True, maximum=stroke_um)
    if kind == "tray_amp_um" and max(amps) > tray_max_um:
        raise grid.error("tray_amp_um", f"request {max(amps):g} um is above interlock.tray_max_um "
                                        f"= {tray_max_um:g} um", f"amplitudes <= {tray_max_um:g} um")
    return ShakerConfig(str(path), text, instruments, gain_db, attenuator_db, current_limit_a, max_input_vrms,
                        payload_kg, envelope, freqs, kind, amps, control, method, robot_spot, video_s, scope,
                        scale, tray_max_um, on_interlock, accel)


# ----------------------------------------------------------------------------- pieces

def _instruments(t: Table, required: tuple[str, ...], optional: tuple[str, ...]) -> dict[str, InstrumentSpec]:
    t.only(required + optional)
    out = {}
    for role in required + optional:
        if role not in t and role not in required:
            continue
        spec = t.table(role)
        model = spec.string("model")
        if role == "camera" and model in ("OpenCVCamera", "FileCamera"):
            resource = str(spec.data.get("resource", ""))
        else:
            resource = spec.string("resource")
        settings = {k: v for k, v in spec.data.items() if k not in ("model", "resource")}
        if role in ("funcgen", "scope", "vibrometer"):
            _check_driver(spec, model, settings)
        out[role] = InstrumentSpec(role, model, resource, settings)
    return out


#: cycles one generator burst may hold (the drivers' and the generators' limit)
MAX_BURST_CYCLES = 1e8


def _check_point_lengths(t: Table, method: Method, freqs: tuple[float, ...], video_s: float = 0.0) -> None:
    """Each point's record fits the scope and its burst fits the generator, at every frequency."""
    if method.kind != "stepped":
        return
    for f in freqs:
        dwell = method.dwell_time_s(f)
        if dwell > MAX_SETTLE_S:
            raise t.error("dwell_cycles", f"{method.dwell_cycles:g} cycles at {f:g} Hz last {dwell:.4g} s",
                          f"a record of at most {MAX_SETTLE_S:g} s at every frequency")
        settle = method.settle_time_s(f)
        if settle > MAX_SETTLE_S:
            raise t.error("settle_cycles" if method.settle_s is None else "settle_s",
                          f"{settle:.4g} s of settling at {f:g} Hz", f"at most {MAX_SETTLE_S:g} s")
        cycles = (settle + max(dwell, video_s)) * f + 2
        if cycles > MAX_BURST_CYCLES:
            key = "dwell_cycles" if dwell >= settle else ("settle_cycles" if method.settle_s is None else "settle_s")
            raise t.error(key, f"a point at {f:g} Hz needs a burst of {cycles:.4g} cycles",
                          f"settle + dwell of at most {MAX_BURST_CYCLES:g} cycles")


def _envelope_defaults() -> dict[str, float]:
    from labkit.drivers.shaker import Shaker4809Envelope

    published = Shaker4809Envelope()
    return {k: float(getattr(published, k)) for k in ENVELOPE_KEYS}


def _envelope_value(shaker: Table, key: str) -> float:
    """A declared envelope value: it may make the envelope smaller, never larger than the 4809's."""
    published = float(_envelope_defaults()[key])
    if key in ("freq_min_hz", "moving_mass_kg"):      # larger is stricter
        return shaker.number(key, minimum=published, maximum=1e6 if key == "freq_min_hz" else 100.0,
                             unit="Hz" if key == "freq_min_hz" else "kg")
    units = {"freq_max_hz": "Hz", "force_peak_n": "N", "stroke_peak_mm": "mm", "velocity_peak_m_s": "m/s"}
    return shaker.number(key, minimum=0, exclusive_minimum=True, maximum=published, unit=units[key])


def _check_generator_band(root: Table, table: str, key: str, freqs: tuple[float, ...],
                          instruments: dict[str, InstrumentSpec]) -> None:
    """Every frequency within what the generator can put out (its family's published maximum)."""
    from labkit.drivers.registry import driver_class

    cls = driver_class(instruments["funcgen"].model)
    top = FUNCGEN_MAX_HZ.get(getattr(cls, "model", ""), min(FUNCGEN_MAX_HZ.values()))
    declared = instruments["funcgen"].settings.get("max_freq_hz")
    if isinstance(declared, (int, float)) and not isinstance(declared, bool) and 0 < declared < top:
        top = float(declared)
    for i, f in enumerate(freqs):
        if f > top:
            name = f"{key}[{i}]" if key.endswith("list_hz") or key == "freq_hz" else key
            raise root.table(table).error(name, f"{f:g} Hz is above what the {cls.model} generator may put out",
                                          f"frequencies <= {top:g} Hz")


def _check_driver(spec: Table, model: str, settings: Mapping[str, TomlValue]) -> None:
    """The model must have a driver, and every extra key must be one of its settings."""
    from labkit.drivers.registry import driver_class, model_names
    from labkit.errors import ConfigError

    try:
        cls = driver_class(model)
    except ConfigError:
        raise spec.error("model", f"unknown instrument model {model!r}",
                         "one of " + ", ".join(model_names())) from None
    allowed = cls.setting_names() - {"name"}
    for key in settings:
        if key not in allowed:
            raise spec.error(key, f"not a setting of the {cls.model} driver", "one of " + ", ".join(sorted(allowed)))
        value = settings[key]
        if isinstance(value, float) and not math.isfinite(value):
            raise spec.error(key, f"not finite: {value!r}", "a finite number")
    if "timeout_s" in settings:
        spec.number("timeout_s", unit="s", minimum=1e-3, maximum=MAX_TIMEOUT_S)
    channels = getattr(cls, "channels", None)
    if "channel" in settings and channels:
        # the family's channel count (the identified model may have fewer: checked at connect)
        spec.integer("channel", minimum=1, maximum=max(channels))


def _frequencies(t: Table) -> tuple[float, ...]:
    t.only(("list_hz", "start_hz", "stop_hz", "count", "spacing"))
    if "list_hz" in t:
        for k in ("start_hz", "stop_hz", "count", "spacing"):
            if k in t:
                raise t.error(k, "given together with list_hz", "either list_hz or start_hz/stop_hz/count")
        return t.numbers("list_hz", unit="Hz", minimum=0, exclusive_minimum=True)
    start = t.number("start_hz", unit="Hz", minimum=0, exclusive_minimum=True)
    stop = t.number("stop_hz", unit="Hz", minimum=start)
    count = t.integer("count", minimum=1, maximum=100_000)
    spacing = t.string("spacing", choices=("lin", "log"), default="log", lower=True)
    if count == 1:
        return (start,)
    values = np.geomspace(start, stop, count) if spacing == "log" else np.linspace(start, stop, count)
    return tuple(float(v) for v in values)


def _method(t: Table, *, allow_chirp: bool) -> Method:
    kinds = ("stepped", "chirp") if allow_chirp else ("stepped",)
    kind = t.string("kind", choices=kinds, default="stepped", lower=True)
    if kind == "chirp":
        t.only(("kind", "length_s", "averages", "keep_raw"))
        return Method(kind, length_s=t.number("length_s", unit="s", minimum=0, exclusive_minimum=True,
                                              maximum=MAX_SETTLE_S),
                      averages=t.integer("averages", default=1, minimum=1, maximum=1000),
                      keep_raw=t.boolean("keep_raw", default=False))
    t.only(("kind", "settle_s", "settle_cycles", "dwell_cycles", "keep_raw"))
    if "settle_s" in t and "settle_cycles" in t:
        raise t.error("settle_s", "given together with settle_cycles", "one of settle_s or settle_cycles")
    if "settle_s" not in t and "settle_cycles" not in t:
        raise t.error("settle_cycles", "missing", "settle_s (s) or settle_cycles (drive periods)")
    settle_s = t.number("settle_s", default=None, unit="s", minimum=0, maximum=MAX_SETTLE_S)
    settle_cycles = t.number("settle_cycles", default=None, minimum=0, maximum=1e7)
    dwell = t.number("dwell_cycles", minimum=1, maximum=1e7)
    if not math.isfinite(dwell):
        raise t.error("dwell_cycles", "not finite", "a number >= 1")
    return Method(kind, settle_s=settle_s, settle_cycles=settle_cycles, dwell_cycles=dwell,
                  keep_raw=t.boolean("keep_raw", default=False))


def _scope(t: Table, model: str = "") -> ScopeSetup:
    t.only(("drive_channel", "velocity_channel", "drive_volts_per_div", "velocity_volts_per_div",
            "trigger_source", "samples_per_cycle", "max_points", "acquisition", "averages"))
    d = t.integer("drive_channel", minimum=1, maximum=4)
    v = t.integer("velocity_channel", minimum=1, maximum=4)
    if d == v:
        raise t.error("velocity_channel", f"same channel as drive_channel ({d})", "a different scope channel")
    trig = t.string("trigger_source", default=None, choices=("EXT", "CHAN1", "CHAN2", "CHAN3", "CHAN4"))
    if trig == "EXT" and _no_ext_input(model):
        raise t.error("trigger_source", f"the {model} has no external trigger input",
                      "CHAN1..CHAN4 (or no setting: the drive channel)")
    return ScopeSetup(d, v,
                      t.number("drive_volts_per_div", default=None, unit="V/div", minimum=0, exclusive_minimum=True),
                      t.number("velocity_volts_per_div", default=None, unit="V/div", minimum=0,
                               exclusive_minimum=True),
                      trig,
                      t.number("samples_per_cycle", default=100.0, minimum=8, maximum=MAX_SAMPLES_PER_CYCLE),
                      t.integer("max_points", default=100_000, minimum=100, maximum=8_000_000),
                      *_acquisition(t, model))


def _no_ext_input(model: str) -> bool:
    """A scope model named in the config that has no EXT TRIG input (the four-channel DS1000Z)."""
    from labkit.drivers.scope import RigolDS1000Z

    name = "".join(ch for ch in str(model).upper() if ch.isalnum())
    return name in RigolDS1000Z.NO_EXT_MODELS


def _acquisition(t: Table, model: str) -> tuple[str, int]:
    """``acquisition`` and ``averages``: 1 with "normal"; 2..65536 with "average" (the DS1000Z: powers of
    two 2..1024, its :ACQuire:AVERages)."""
    acq = t.string("acquisition", default="normal", choices=("normal", "average"))
    rigol = model == "DS1000Z"
    expected = "1 with acquisition = 'normal'; with 'average' " + (
        "a power of two 2..1024 (DS1000Z)" if rigol else "2..65536")
    n = t.integer("averages", default=1, minimum=1, maximum=1024 if rigol else 65536)
    if (acq == "average") != (n > 1) or (rigol and n & (n - 1)):
        raise t.error("averages", f"{n} with acquisition = {acq!r}", expected)
    return acq, n


def comparable(cfg: InchipConfig | ShakerConfig) -> dict[str, Json]:
    """The config as a dict with resources left out, for matching a resumed run's config.

    Resources may change between sessions (a virtual lab's ports, a renumbered
    serial port); what was measured and how may not.
    """
    import dataclasses

    d = dataclasses.asdict(cfg)
    d.pop("path")
    d.pop("text")
    d["instruments"] = {role: {"model": s["model"], "settings": s["settings"]}
                        for role, s in d["instruments"].items() if role != "control"}
    return d
