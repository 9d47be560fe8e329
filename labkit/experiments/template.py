"""Commented experiment configs (TOML) for ``labkit init`` and ``labkit lab serve``.

Every key is written with its unit, its default (when it may be left out) and
its limit, as :mod:`labkit.experiments.config` checks them. What only the
person at the bench can know (which scope channel sees the drive and which the
vibrometer, the decoder's range, the amplifier's gain switch) is written as the
string ``"TODO"`` with a ``# TODO:`` comment: such a config does not load until
each is replaced, and :func:`todo_keys` lists the ones left.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

from labkit.errors import ConfigError

TODO = '"TODO"'


@dataclass(frozen=True)
class Instrument:
    """One instrument for the template: driver model, resource, and what ``identify`` read (if anything)."""

    model: str | None          # None: not found (written as a TODO)
    resource: str | None
    identity: str = ""
    settings: dict[str, object] = field(default_factory=dict)


@dataclass(frozen=True)
class Wiring:
    """What only the bench knows; None is written as a TODO."""

    drive_channel: int | None = None
    velocity_channel: int | None = None
    scale_mm_s_per_v: float | None = None
    gain_db: float | None = None
    accel_m_s2_per_v: float | None = None


@dataclass(frozen=True)
class Band:
    """The frequencies of an in-chip sweep, or the grid of a shaker run."""

    start_hz: float = 300.0
    stop_hz: float = 5000.0
    count: int = 200


def _value(v: object) -> str:
    if v is None:
        return TODO
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, bool):
        return "true" if v else "false"
    return repr(float(v)) if isinstance(v, float) else str(v)


def _line(key: str, value: object, comment: str, todo: str = "") -> str:
    text = f"{key} = {_value(value)}"
    note = f"TODO: {todo} -- {comment}" if value is None and todo else comment
    return f"{text:<33} # {note}"


def _instruments(instruments: dict[str, Instrument], control: str | None) -> list[str]:
    about = {"funcgen": "function generator (labkit drivers: 33220A, 33500B, DG1000Z)",
             "scope": "oscilloscope (labkit drivers: InfiniiVision, DS1000Z)",
             "vibrometer": "vibrometer controller (labkit drivers: OFV-5000, OFV-3001)",
             "camera": "camera"}
    out: list[str] = []
    for role, inst in instruments.items():
        out.append(f"[instruments.{role}]".ljust(34) + f"# {about.get(role, role)}"
                   + (f"; identifies as {inst.identity!r}" if inst.identity else ""))
        out.append(_line("model", inst.model, "the labkit driver (required)", f"no {role} identified: its driver"))
        out.append(_line("resource", inst.resource, "VISA resource or serial port (required)",
                         f"the {role}'s address (labkit devices)"))
        for key, value in inst.settings.items():
            out.append(_line(key, value, "driver setting"))
        if role == "funcgen" and "channel" not in inst.settings:
            out.append(_line("channel", 1, "output that drives the chain (default 1; 1..the model's channels)"))
        out.append("# timeout_s = 2.0                 # per command, s (default 2)")
        out += driver_settings(inst.model, skip=set(inst.settings) | {"channel"})
        out.append("")
    if control is not None:
        out += ["[instruments.control]             # the virtual lab's control channel: the run moves "
                "the laser itself",
                _line("model", "LabControl", "the virtual lab's control channel (optional table)"),
                _line("resource", control, "its socket"), ""]
    return out


#: the drivers' settings: an example value (for those without a default) and what each is
_SETTINGS: dict[str, tuple[object, str]] = {
    "max_amp_vpp": (20.0, "Vpp, the amplitude limit, 0..20 (default: none beyond the model's 20 Vpp)"),
    "max_v": (10.0, "V, limit of |offset| + amplitude/2, 0..10 (in-chip the run also applies drive.pzt_max_v)"),
    "max_freq_hz": (100000.0, "Hz, highest frequency allowed (default: the family's maximum)"),
    "check_errors": (True, "read the error queue after each group of settings (default true)"),
    "points": ("MAX", "record points read back: \"MAX\" or 100..8000000 (default \"MAX\")"),
    "channels": (4, "analog inputs; must agree with the model (default: from its identity)"),
    "max_volts_per_div": (10.0, "V/div, refuse larger vertical scales (default 10)"),
    "max_block_bytes": (250000, "bytes per :WAV:DATA? block, 2..250000 (default 250000)"),
    "decoder_index": (1, "the velocity decoder's index (default 1)"),
    "ranges_mm_s_per_v": ([1.0, 5.0, 25.0, 125.0, 1000.0], "mm/s/V, the decoder's ranges (default: verified by "
                          "reading back)"),
    "over_range_command": ("Get,VeloDec,{i},OverRange", "over-range query (unverified; {i} the decoder index)"),
    "identity_command": ("GetDevInfo,Controller,0,Name", "identity query (unverified)"),
    "decoder": ("OVD-01", "\"OVD-01\" or \"OVD-02\": the range-number table (default \"OVD-01\")"),
    "serial_number": ("", "recorded in the identity (default empty)"),
    "baud_rate": (9600, "serial baud rate"),
}


def driver_settings(model: str | None, skip: set[str] = frozenset()) -> list[str]:  # type: ignore[assignment]
    """Commented lines for the settings of ``model``'s driver, with their defaults (none for an unknown model)."""
    import inspect

    from labkit.drivers.registry import driver_class

    if model is None:
        return []
    try:
        cls = driver_class(model)
    except ConfigError:
        return []
    defaults: dict[str, object] = {}
    for klass in cls.__mro__:
        init = klass.__dict__.get("__init__")
        for prm in (inspect.signature(init).parameters.values() if init is not None else ()):
            if prm.kind == prm.KEYWORD_ONLY and prm.name not in defaults:
                defaults[prm.name] = prm.default
    defaults.update(cls.transport_defaults)
    out = []
    for key, default in defaults.items():
        if key in skip or key not in _SETTINGS:
            continue
        example, what = _SETTINGS[key]
        shown = example if default is None else default
        val = "[" + ", ".join(repr(x) for x in shown) + "]" if isinstance(shown, list) else _value(shown)
        note = what if default is not None or "default" in what else what + " (default: none)"
        if key == "baud_rate":
            note = f"{what} (default {default})"
        out.append(f"{'# ' + key + ' = ' + val:<33} # {note}")
    return out


def _scope(w: Wiring) -> list[str]:
    return ["[scope]",
            _line("drive_channel", w.drive_channel, "scope channel (1-4) cabled to the generator output",
                  "which scope channel sees the drive?"),
            _line("velocity_channel", w.velocity_channel, "scope channel (1-4) cabled to the vibrometer's "
                  "analog output; not the drive's", "which scope channel sees the vibrometer?"),
            '# trigger_source = "EXT"          # "EXT" (generator SYNC -> scope EXT TRIG) or "CHAN1".."CHAN4"; '
            "default: EXT, the drive channel on a scope without EXT (4-channel DS1000Z)",
            _line("samples_per_cycle", 100.0, "record points per drive period, >= 8 (default 100)"),
            _line("max_points", 100000, "cap on record points, 100..8000000 (default 100000)"),
            '# acquisition = "average"         # "normal" (default) or "average": the scope averages `averages` '
            "triggered records per point",
            "# averages = 16                   # with \"average\": 2..65536 (DS1000Z: a power of two 2..1024)",
            "# drive_volts_per_div = 0.5       # V/div, > 0 (default: from the drive amplitude)",
            "# velocity_volts_per_div = 2.5    # V/div, > 0 (default: the vibrometer's +-10 V, then narrowed)",
            ""]


def _vibrometer(w: Wiring) -> list[str]:
    return ["[vibrometer]",
            _line("scale_mm_s_per_v", w.scale_mm_s_per_v, "velocity decoder range, mm/s per V, > 0 "
                  "(e.g. 1, 5, 25, 125, 1000); the run sets the controller to it",
                  "the decoder range you want"), ""]


def _header(kind: str, command: str) -> list[str]:
    return [f"# labkit {kind} config, written by 'labkit init'. Each key: its unit, its default (if it may",
            "# be left out) and its limit. Replace every \"TODO\" (what only the bench knows), then run:",
            f"#   {command}", ""]


def _footer(check: str, run: str) -> list[str]:
    return ["# next, once no \"TODO\" is left:", f"#   {check}", f"# then the run:  {run}", ""]


def inchip_text(instruments: dict[str, Instrument], wiring: Wiring, *, control: str | None = None,
                band: Band = Band(), path: str = "CONFIG.toml") -> str:
    """An in-chip sweep config (``labkit sweep inchip``): see the module docstring."""
    lines = _header("in-chip sweep", f"labkit check {path}")
    lines += ["[run]",
              _line("locations", "__LOC__", 'laser spots in order, from "body", "hip", "knee" (default all three)'),
              _line("on_interlock", "skip", '"skip" the point or "end" the run (default "skip")'), ""]
    lines += _instruments(instruments, control)
    lines += ["[drive]                           # the generator drives the PZT directly (no amplifier)",
              _line("amp_vpp", 4.0, "Vpp at the PZT, > 0 (required); |offset_v| + amp_vpp/2 <= pzt_max_v and "
                    "<= 10 V"),
              _line("offset_v", 2.0, "V (default 0): unipolar drive of the film"),
              _line("pzt_max_v", 20.0, "V, the film's limit (default 20; at most 20)"), "",
              "[frequencies]                     # or: list_hz = [400.0, 800.0] (Hz, > 0)",
              _line("start_hz", float(band.start_hz), "Hz, > 0 (required)"),
              _line("stop_hz", float(band.stop_hz), "Hz, >= start_hz and <= the generator's maximum (required)"),
              _line("count", int(band.count), "points, 1..100000 (required)"),
              _line("spacing", "log", '"log" or "lin" (default "log")'), "",
              "[method]",
              _line("kind", "stepped", '"stepped" (default) or "chirp" (keys length_s, averages)'),
              _line("settle_s", 0.05, "s before each record, 0..600 (or settle_cycles: drive periods; one of the two)"),
              _line("dwell_cycles", 20.0, "drive periods recorded per point, 1..1e7 (required)"),
              _line("keep_raw", False, "keep every point's scope records (default false)"), ""]
    lines += _scope(wiring) + _vibrometer(wiring)
    lines += _footer(f"labkit check {path}", f"labkit sweep inchip {path} --out run.h5")
    return "\n".join(lines).replace('"__LOC__"', '["body", "hip", "knee"]')


def _envelope_lines() -> list[str]:
    """The 4809's published envelope, commented (a value may be lowered, never raised)."""
    from labkit.drivers.shaker import Shaker4809Envelope
    from labkit.experiments.config import ENVELOPE_KEYS

    env = Shaker4809Envelope()
    units = {"freq_min_hz": "Hz (may only be raised)", "freq_max_hz": "Hz", "force_peak_n": "N",
             "stroke_peak_mm": "mm", "velocity_peak_m_s": "m/s", "moving_mass_kg": "kg (may only be raised)"}
    return [f"{'# ' + k + ' = ' + repr(float(getattr(env, k))):<33} # {units[k]}, the 4809's (default)"
            for k in ENVELOPE_KEYS]


def shaker_text(instruments: dict[str, Instrument], wiring: Wiring, *, control: str | None = None,
                band: Band = Band(150.0, 300.0, 3), path: str = "CONFIG.toml") -> str:
    """A shaker-run config (``labkit shaker``): see the module docstring."""
    import numpy as np

    freqs = ", ".join(repr(round(float(f), 3)) for f in np.geomspace(band.start_hz, band.stop_hz, band.count))
    lines = _header("shaker", f"labkit check {path}")
    lines += ["[run]",
              _line("robot_spot", "knee", 'where the robot is measured: "knee", "hip" or "body" (default "knee")'),
              _line("video_s", 0.0, "s filmed per point, 0..600 (default 0: no camera)"),
              _line("on_interlock", "skip", '"skip" the point or "end" the run (default "skip")'), ""]
    lines += _instruments(instruments, control)
    lines += ["[amplifier]                       # B&K 2718: no remote interface, so declared as set",
              _line("gain_db", wiring.gain_db, "dB, the gain switch: 20 or 40 (required)",
                    "where is the amplifier's gain switch?"),
              _line("attenuator_db", 0.0, "dB, >= 0 (required)"),
              _line("current_limit_a", 1.0, "A, > 0 (required)"),
              "# max_input_vrms = 0.8            # V rms, input cap: at most 0.8 at 20 dB, 0.08 at 40 dB "
              "(default those)", "",
              "[shaker]                          # B&K 4809 envelope (each value may only be made stricter)",
              _line("payload_kg", 0.002, "kg on the table, 0..10 (default 0)"),
              *_envelope_lines(),
              _line("accel_m_s2_per_v", wiring.accel_m_s2_per_v, "m/s^2 per V at the amplifier output, > 0 "
                    "(optional): lets 'labkit check' verify the amplifier gain", "the shaker's sensitivity from its "
                    "calibration (or delete this line: the gain is then not checked)"), "",
              "[grid]",
              f"freq_hz = [{freqs}]".ljust(34) + "# Hz, within 10..20000 (the 4809) (required)",
              _line("tray_amp_um", "__AMP__", "um tray displacement, > 0 and <= interlock.tray_max_um "
                    "(or drive_vpp = [...] Vpp)"), "",
              "[tray_control]",
              _line("tolerance", 0.02, "relative, 0..0.5 (default 0.02)"),
              _line("max_iterations", 8, "1..50 (default 8)"),
              _line("start_vpp", 0.05, "Vpp, first drive at a frequency, > 0 and <= the input cap (default 0.05)"),
              _line("max_step_ratio", 4.0, "> 1 (default 4)"), "",
              "[method]",
              _line("settle_s", 0.1, "s, 0..600 (or settle_cycles)"),
              _line("dwell_cycles", 20.0, "drive periods recorded per point, 1..1e7 (required)"), ""]
    lines += _scope(wiring) + _vibrometer(wiring)
    lines += ["[interlock]", _line("tray_max_um", 60.0, "um, > 0 and <= 4000 (the 4809's stroke) (required)"), ""]
    lines += _footer(f"labkit check {path}", f"labkit shaker {path} --out run.h5")
    return "\n".join(lines).replace('"__AMP__"', "[10.0, 25.0]")


_TODO_LINE = re.compile(r'^\s*([A-Za-z_][A-Za-z0-9_]*)\s*=\s*"TODO"')


def todo_keys(path: str | Path) -> list[str]:
    """The dotted keys of a config still set to ``"TODO"`` (empty when none is left)."""
    table, keys = "", []
    try:
        text = Path(path).read_text()
    except OSError as exc:
        raise ConfigError(f"cannot read: {exc.strerror or exc}", file=path) from None
    for line in text.splitlines():
        s = line.split("#", 1)[0].strip()
        if s.startswith("[") and s.endswith("]"):
            table = s.strip("[]").strip()
            continue
        m = _TODO_LINE.match(line)
        if m:
            keys.append(f"{table}.{m.group(1)}" if table else m.group(1))
    return keys


#: the virtual lab's cabling (labkit.lab.core): generator 1 -> scope 1, vibrometer -> scope 2, SYNC -> EXT;
#: its amplifier's gain switch at 20 dB, its shaker's sensitivity 20 m/s^2/V (labkit.lab.physics.ShakerChain)
LAB_WIRING = Wiring(drive_channel=1, velocity_channel=2, scale_mm_s_per_v=25.0, gain_db=20.0, accel_m_s2_per_v=20.0)


def lab_config_text(setup: str, resources: dict[str, str], models: dict[str, str], *, path: str = "CONFIG.toml",
                    band: Band | None = None) -> str:
    """The config of a virtual lab (``labkit lab serve``, ``labkit init --lab``): no TODO left."""
    inst = {role: Instrument(models[role], resources[role]) for role in ("funcgen", "scope", "vibrometer")}
    if setup == "shaker":
        return shaker_text(inst, LAB_WIRING, control=resources.get("control"), path=path,
                           band=band or Band(150.0, 300.0, 3))
    return inchip_text(inst, LAB_WIRING, control=resources.get("control"), path=path, band=band or Band())
