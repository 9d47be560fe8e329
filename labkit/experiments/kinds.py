"""The experiment kinds in one registry: ``inchip`` (tethered robot, PZT driven directly) and ``shaker``.

Everything that differs between the kinds lives here, one :class:`ExperimentKind`
each, so the session, the rig and the run file never branch on a kind's name:

* ``load``       config file -> validated config (:mod:`labkit.experiments.config`)
* ``plan``       config, done indices -> :class:`labkit.experiments.plans.Plan`
* ``preflight``  every limit checked from the declared chain before anything is opened
* ``run_attrs``  the kind's root attributes of a run file
* ``layout``     the kind's run-file tables (extra ``/points`` columns, per-location tables)
* ``rig_setup``  the generator limits and the declared amplifier/shaker for the rig
* ``point_bytes`` about how many bytes one point adds to the run file (the free-space pre-flight)

Add a kind by registering one more :class:`ExperimentKind` in :data:`KINDS`.
"""
from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from labkit.errors import InputError, LimitError
from labkit.experiments.config import InchipConfig, ShakerConfig, load_inchip, load_shaker
from labkit.experiments.plans import Plan, inchip_plan, shaker_plan
from labkit.experiments.protocols import Amplifier, ShakerEnvelope

Config = InchipConfig | ShakerConfig
Fields = dict[str, tuple[str, str]]


@dataclass(frozen=True)
class RigSetup:
    """What the rig needs to know about a kind's drive chain before it opens the generator."""

    funcgen_limits: dict[str, float]        # declared limits handed to the generator driver
    amplifier: Amplifier | None = None      # the declared power amplifier (shaker)
    envelope: ShakerEnvelope | None = None  # the shaker's envelope
    drive: tuple[float, float] | None = None  # (amp_vpp, offset_v) known at set-up (in-chip)
    wants_camera: bool = False
    payload_kg: float = 0.0                 # on the shaker's table (its envelope's moving mass grows)


@dataclass(frozen=True)
class ExperimentKind:
    """One kind of experiment (see the module docstring for each member)."""

    name: str
    file_kind: str          # the run file's ``kind`` attribute
    lab_setup: str          # the virtual lab's set-up for this kind
    load: Callable[[str | Path], Any]
    plan: Callable[[Any, Iterable[int]], Plan]
    preflight: Callable[[Any], None]
    run_attrs: Callable[[Any], dict[str, str | float]]
    layout: Callable[[Any], tuple[Fields, dict[str, Fields]]]
    rig_setup: Callable[[Any], RigSetup]
    point_bytes: Callable[[Any], float]     # about how much one point adds to the run file


#: per point, beyond its records: table rows, the events of a point, HDF5 chunk and group overhead
POINT_OVERHEAD_BYTES = 8192


def _record_points(cfg: Config, record_s_cycles: float) -> int:
    return int(min(cfg.scope.max_points, max(100, record_s_cycles)))


# ----------------------------------------------------------------------------- in-chip

def _inchip_preflight(cfg: InchipConfig) -> None:
    """The PZT limit is checked while loading the config; nothing else to predict."""


def _inchip_attrs(cfg: InchipConfig) -> dict[str, str | float]:
    return {"drive_amp_vpp": cfg.amp_vpp, "drive_offset_v": cfg.offset_v, "pzt_max_v": cfg.pzt_max_v,
            "method": cfg.method.kind}


def _inchip_layout(cfg: InchipConfig) -> tuple[Fields, dict[str, Fields]]:
    from labkit.experiments.runfile import CHIRP_FIELDS, STEPPED_FIELDS

    fields = CHIRP_FIELDS if cfg.method.kind == "chirp" else STEPPED_FIELDS
    return {}, {f"locations/{loc}": fields for loc in cfg.locations}


def _inchip_bytes(cfg: InchipConfig) -> float:
    m = cfg.method
    if m.kind == "chirp":
        n = _record_points(cfg, m.length_s * max(cfg.freqs_hz) * 10)
        rows = n / 2 * 48                                   # one FRF line per frequency bin
        raw = 2 * 4 * n * m.averages if m.keep_raw else 0
        return rows + raw + POINT_OVERHEAD_BYTES
    raw = 2 * 4 * _record_points(cfg, m.dwell_cycles * cfg.scope.samples_per_cycle) if m.keep_raw else 0
    return raw + POINT_OVERHEAD_BYTES


def _inchip_rig(cfg: InchipConfig) -> RigSetup:
    return RigSetup(funcgen_limits={"max_v": min(cfg.pzt_max_v, 10.0)}, drive=(cfg.amp_vpp, cfg.offset_v))


# ----------------------------------------------------------------------------- shaker

def shaker_chain(cfg: ShakerConfig) -> tuple[Amplifier, ShakerEnvelope]:
    """The declared 2718 amplifier and the 4809 envelope of a shaker config."""
    from labkit.drivers.shaker import Amplifier2718, Shaker4809Envelope

    amp = Amplifier2718(gain_db=cfg.gain_db, attenuator_db=cfg.attenuator_db,
                        current_limit_a=cfg.current_limit_a, max_input_vrms=cfg.max_input_vrms)
    return amp, Shaker4809Envelope(**cfg.envelope)


def _shaker_preflight(cfg: ShakerConfig) -> None:
    """Check every limit that needs no instrument, before anything is opened.

    Raises
    ------
    LimitError
        Naming the config file and key: a drive above the amplifier's input
        cap, a requested tray amplitude outside the shaker's envelope.
    """
    amp, env = shaker_chain(cfg)
    _check_band(cfg, env)
    if cfg.amplitude_kind == "drive_vpp" and cfg.accel_m_s2_per_v is not None:
        _check_predicted_travel(cfg, amp, env)
    if cfg.amplitude_kind == "drive_vpp":
        _check_drives(cfg, amp)
    else:
        _check_tray_amplitudes(cfg, env)


def _check_band(cfg: ShakerConfig, env: ShakerEnvelope) -> None:
    """Every frequency within the shaker's band, whatever the amplitudes are given as."""
    for i, f in enumerate(cfg.freqs_hz):
        if not env.freq_min_hz <= f <= env.freq_max_hz:
            raise LimitError(f"{f:g} Hz is outside the 4809 frequency range {env.freq_min_hz:g}-"
                             f"{env.freq_max_hz:g} Hz; nothing was sent", limit="frequency", file=cfg.path,
                             key=f"grid.freq_hz[{i}]",
                             expected=f"{env.freq_min_hz:g} <= freq_hz <= {env.freq_max_hz:g}")


def _check_predicted_travel(cfg: ShakerConfig, amp: Amplifier, env: ShakerEnvelope) -> None:
    """Drives given in volts with a declared sensitivity: the tray's predicted travel within the interlock
    and the envelope. The declared chain predicts it: x = a / w^2 with a = sensitivity * gain * V (the mass
    line; below the suspension's resonance the tray moves less: conservative)."""
    assert cfg.accel_m_s2_per_v is not None
    for i, f in enumerate(cfg.freqs_hz):
        for j, v in enumerate(cfg.amplitudes):
            x_um = 1e6 * cfg.accel_m_s2_per_v * amp.voltage_gain * v / 2 / (2 * math.pi * f) ** 2
            key = f"grid.drive_vpp[{j}] at grid.freq_hz[{i}]"
            if x_um > cfg.tray_max_um:
                raise LimitError(f"{v:g} Vpp at {f:g} Hz is predicted to move the tray {x_um:.4g} um "
                                 f"(declared shaker.accel_m_s2_per_v = {cfg.accel_m_s2_per_v:g}), above "
                                 f"interlock.tray_max_um = {cfg.tray_max_um:g} um; nothing was sent",
                                 limit="tray_max_um", file=cfg.path, key=key)
            try:
                env.check(f, x_um, payload_kg=cfg.payload_kg)
            except LimitError as exc:
                raise LimitError(f"{v:g} Vpp at {f:g} Hz is predicted to move the tray {x_um:.4g} um: "
                                 + exc.message, limit=exc.limit, file=cfg.path, key=key) from None


def _check_drives(cfg: ShakerConfig, amp: Amplifier) -> None:
    """Drives given in volts: each within the amplifier's input cap. Without a declared sensitivity the
    runner ramps each point up from tray_control.start_vpp, measuring the tray and predicting the next
    step (soft start)."""
    for i, v in enumerate(cfg.amplitudes):
        try:
            amp.check_input(v)
        except LimitError as exc:
            raise LimitError(exc.message, limit=exc.limit, file=cfg.path, key=f"grid.drive_vpp[{i}]",
                             expected=f"<= {amp.max_input_vpp:.4g} Vpp at {cfg.gain_db:g} dB") from None


def _check_tray_amplitudes(cfg: ShakerConfig, env: ShakerEnvelope) -> None:
    """Tray amplitudes requested: each within the shaker's envelope at its frequency."""
    for i, f in enumerate(cfg.freqs_hz):
        for j, a in enumerate(cfg.amplitudes):
            try:
                env.check(f, a, payload_kg=cfg.payload_kg)
            except LimitError as exc:
                raise LimitError(exc.message, limit=exc.limit, file=cfg.path,
                                 key=f"grid.tray_amp_um[{j}] at grid.freq_hz[{i}]",
                                 expected=f"<= {env.max_disp_amp_um(f, cfg.payload_kg):.4g} um "
                                          f"at {f:g} Hz") from None


def _shaker_attrs(cfg: ShakerConfig) -> dict[str, str | float]:
    return {"robot_spot": cfg.robot_spot, "amplitude_kind": cfg.amplitude_kind,
            "amplifier_json": json.dumps({"gain_db": cfg.gain_db, "attenuator_db": cfg.attenuator_db,
                                          "current_limit_a": cfg.current_limit_a,
                                          "max_input_vrms": cfg.max_input_vrms}),
            "shaker_json": json.dumps({"payload_kg": cfg.payload_kg, "envelope": cfg.envelope})}


def _shaker_layout(cfg: ShakerConfig) -> tuple[Fields, dict[str, Fields]]:
    from labkit.experiments.runfile import SHAKER_FIELDS

    return dict(SHAKER_FIELDS), {}


def _shaker_bytes(cfg: ShakerConfig) -> float:
    # four float32 records (tray and robot velocity, the drive at each) of a dwell each
    return 4 * 4 * _record_points(cfg, cfg.method.dwell_cycles * cfg.scope.samples_per_cycle) + POINT_OVERHEAD_BYTES


def _shaker_rig(cfg: ShakerConfig) -> RigSetup:
    amp, env = shaker_chain(cfg)
    cap = float(amp.max_input_vpp)
    return RigSetup(funcgen_limits={"max_amp_vpp": cap, "max_v": cap / 2}, amplifier=amp, envelope=env,
                    wants_camera=cfg.video_s > 0, payload_kg=cfg.payload_kg)


# ----------------------------------------------------------------------------- the registry

KINDS: dict[str, ExperimentKind] = {
    "inchip": ExperimentKind("inchip", "run_inchip", "inchip", load_inchip, inchip_plan, _inchip_preflight,
                             _inchip_attrs, _inchip_layout, _inchip_rig, _inchip_bytes),
    "shaker": ExperimentKind("shaker", "run_shaker", "shaker", load_shaker, shaker_plan, _shaker_preflight,
                             _shaker_attrs, _shaker_layout, _shaker_rig, _shaker_bytes),
}


def get(name: str) -> ExperimentKind:
    """The kind registered as ``name`` (InputError naming the known ones otherwise)."""
    try:
        return KINDS[name]
    except KeyError:
        raise InputError(f"unknown experiment kind {name!r}", key="kind",
                         expected="one of " + ", ".join(KINDS)) from None


def of(cfg: Config) -> ExperimentKind:
    """The kind of a validated config."""
    return get(cfg.kind)


def preflight(cfg: Config) -> None:
    """Every limit a config's kind can check without an instrument (raises LimitError)."""
    of(cfg).preflight(cfg)


__all__ = ["Config", "ExperimentKind", "KINDS", "RigSetup", "get", "of", "preflight", "shaker_chain"]
