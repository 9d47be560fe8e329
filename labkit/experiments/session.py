"""One experiment session: config -> limits -> (virtual lab) -> rig -> plan -> runner -> run file.

This is what ``labkit sweep inchip`` and ``labkit shaker`` call.
"""
from __future__ import annotations

import contextlib
import time
from pathlib import Path
from typing import Any, Iterator

from labkit.errors import InputError, LimitError
from labkit.jsonutil import to_jsonable
from labkit.experiments import runfile as rf
from labkit.experiments.config import (InchipConfig, InstrumentSpec, ShakerConfig, comparable, load_inchip,
                                       load_shaker)
from labkit.experiments.plans import Plan, inchip_plan, shaker_plan
from labkit.experiments.safety import shielded


def load(kind: str, path: str | Path) -> InchipConfig | ShakerConfig:
    return load_inchip(path) if kind == "inchip" else load_shaker(path)


def preflight(cfg: InchipConfig | ShakerConfig) -> None:
    """Check every limit that needs no instrument, before anything is opened.

    Raises
    ------
    LimitError
        Naming the config file and key: a drive above the amplifier's input
        cap, a requested tray amplitude outside the shaker's envelope.
    """
    if not isinstance(cfg, ShakerConfig):
        return                          # the PZT limit is checked while loading the config
    from drivers.shaker import Amplifier2718, Shaker4809Envelope

    amp = Amplifier2718(gain_db=cfg.gain_db, attenuator_db=cfg.attenuator_db,
                        current_limit_a=cfg.current_limit_a, max_input_vrms=cfg.max_input_vrms)
    env = Shaker4809Envelope(**cfg.envelope)
    if cfg.amplitude_kind == "drive_vpp":
        for i, v in enumerate(cfg.amplitudes):
            try:
                amp.check_input(v)
            except LimitError as exc:
                raise LimitError(exc.message, limit=exc.limit, file=cfg.path, key=f"grid.drive_vpp[{i}]",
                                 expected=f"<= {amp.max_input_vpp:.4g} Vpp at {cfg.gain_db:g} dB") from None
    else:
        for i, f in enumerate(cfg.freqs_hz):
            for j, a in enumerate(cfg.amplitudes):
                try:
                    env.check(f, a, payload_kg=cfg.payload_kg)
                except LimitError as exc:
                    raise LimitError(exc.message, limit=exc.limit, file=cfg.path,
                                     key=f"grid.tray_amp_um[{j}] at grid.freq_hz[{i}]",
                                     expected=f"<= {env.max_disp_amp_um(f, cfg.payload_kg):.4g} um "
                                              f"at {f:g} Hz") from None


#: the models the virtual lab simulates, by role
LAB_MODELS = {"funcgen": "33500B", "scope": "InfiniiVision", "vibrometer": "OFV-5000", "control": "LabControl"}

#: placeholder resources (TEST-NET addresses, never reached): ``--lab`` replaces them
_PLACEHOLDER_RESOURCES = {"funcgen": "TCPIP0::192.0.2.1::5025::SOCKET",
                          "scope": "TCPIP0::192.0.2.2::5025::SOCKET",
                          "vibrometer": "ASRL/dev/ttyUSB0::INSTR"}


def lab_instruments_toml(roles: tuple[str, ...] = ("funcgen", "scope", "vibrometer")) -> str:
    """The ``[instruments.*]`` tables of a config meant for ``--lab``: the lab's models, placeholder resources."""
    return "\n".join(f'[instruments.{role}]\nmodel = "{LAB_MODELS[role]}"\nresource = "{_PLACEHOLDER_RESOURCES[role]}"\n'
                     for role in roles)


@contextlib.contextmanager
def virtual_lab(cfg: Any, seed: int = 0, lab: Any = None) -> Iterator[tuple[Any, Any]]:
    """Yield ``(lab, cfg pointed at it)``: a new in-process virtual lab, or ``lab`` (left running)."""
    import dataclasses

    from labkit.lab import VirtualLab

    with (contextlib.nullcontext(lab.start()) if lab is not None else VirtualLab(seed=seed)) as lab:
        res = dict(lab.resources)
        models = dict(LAB_MODELS)
        inst = dict(cfg.instruments)
        for role in ("funcgen", "scope", "vibrometer", "control"):
            if role not in res:
                continue
            old = inst.get(role)
            model = models.get(role) or (old.model if old else "LabControl")
            # the lab is wired to generator channel 1; only limits and timeouts carry over
            settings = {k: v for k, v in (old.settings if old else {}).items()
                        if k == "timeout_s" or k.startswith("max")} if role != "control" else {}
            inst[role] = InstrumentSpec(role, model, res[role], settings)
        if "camera" in inst and inst["camera"].model == "LabCamera":
            inst["camera"] = inst["camera"].with_resource(res["control"])
        yield lab, dataclasses.replace(cfg, instruments=inst)


def run_session(kind: str, config: str | Path, out: str | Path | None, *, lab: Any = False,
                resume: str | Path | None = None, quiet: bool = False, seed: int = 0,
                stdin: Any = None) -> dict[str, Any]:
    """Run an in-chip sweep (``kind="inchip"``) or a shaker run; return the JSON summary.

    ``lab``: False (the config's instruments), True (start a virtual lab in-process for
    this run), or a running :class:`labkit.lab.VirtualLab` to use.

    Raises
    ------
    InputError / ConfigError / LimitError
        Bad config or paths (nothing was opened or sent).
    InstrumentError
        An instrument or its link failed (the drive is off).
    KeyboardInterrupt / Interrupted
        Interrupted (the drive is off, the file is finished and readable).
    """
    cfg = load(kind, config)
    preflight(cfg)
    if resume is not None:
        if out is not None and Path(out).resolve() != Path(resume).resolve():
            raise InputError("--out and --resume name different files", key="--out",
                             expected="--resume FILE alone, or the same FILE for both")
        path = Path(resume)
        if not path.is_file():
            raise InputError("no such run file", file=path, key="--resume")
    elif out is None:
        raise InputError("no output file", key="--out", expected="--out FILE (or --resume FILE)")
    else:
        path = Path(out)
        if path.exists():
            raise InputError("already exists; use --resume to continue it, or another --out",
                             file=path, key="--out")
    stack = contextlib.ExitStack()
    with stack:
        lab_obj = None
        if lab is not False and lab is not None:
            lab_obj, cfg = stack.enter_context(virtual_lab(cfg, seed=seed, lab=None if lab is True else lab))
        cfg_json = comparable(cfg)
        run = rf.RunFile.resume(path, cfg, cfg_json) if resume is not None else None   # checks the config
        runner = None
        try:
            from labkit.experiments.rig import PromptSpot, Rig
            from labkit.experiments.runner import Runner

            # a given stdin means a person answers the prompts (even with a lab control channel)
            spot = PromptSpot(stdin=stdin) if stdin is not None else None
            # instruments first (the drive stays off): a rig that cannot be opened leaves no new file
            rig = stack.enter_context(Rig(cfg, spot=spot))
            if run is None:
                n_total = (inchip_plan(cfg) if kind == "inchip" else shaker_plan(cfg)).points_total
                run = rf.RunFile.create(path, cfg, cfg_json, n_total, _extra_attrs(cfg))
            plan: Plan = inchip_plan(cfg, run.done) if kind == "inchip" else shaker_plan(cfg, run.done)
            for role, (model, resource, snap) in rig.snapshots().items():
                run.set_instrument(role, model, resource, snap)
            runner = Runner(rig, run, cfg, quiet=quiet)
            status = runner.run(plan)
        except BaseException as exc:
            if runner is None and run is not None:   # failed before the runner owned the drive: say why
                from labkit.errors import Interrupted

                if isinstance(exc, (KeyboardInterrupt, Interrupted)):
                    why = f"interrupted: {getattr(exc, 'signame', 'SIGINT')}"
                else:
                    why = f"aborted: {type(exc).__name__}: {exc}"
                with shielded():
                    run.event(f"run not started: {why}")
                    run.finish(why)
            raise
        finally:
            with shielded():
                if run is not None:
                    run.close()
                    if lab_obj is not None:
                        _store_lab_record(path, lab_obj)
    out_summary = rf.summary(path)
    out_summary.update(ok=True, status=status)
    if runner is not None:
        out_summary["interlocks"] = runner.interlocks
    return out_summary


def _extra_attrs(cfg: Any) -> dict[str, Any]:
    import json

    if isinstance(cfg, InchipConfig):
        return {"drive_amp_vpp": cfg.amp_vpp, "drive_offset_v": cfg.offset_v, "pzt_max_v": cfg.pzt_max_v}
    return {"robot_spot": cfg.robot_spot, "amplitude_kind": cfg.amplitude_kind,
            "amplifier_json": json.dumps({"gain_db": cfg.gain_db, "attenuator_db": cfg.attenuator_db,
                                          "current_limit_a": cfg.current_limit_a,
                                          "max_input_vrms": cfg.max_input_vrms}),
            "shaker_json": json.dumps({"payload_kg": cfg.payload_kg, "envelope": cfg.envelope})}


def _store_lab_record(path: Path, lab: Any) -> None:
    """The lab's record of when outputs went on and off, in the run file (tests and audits read it)."""
    try:
        timeline = list(lab.output_timeline)
    except Exception:
        return
    offset = time.time() - lab.now_s()
    truth = None
    try:
        truth = to_jsonable(lab.truth)
    except Exception:
        pass
    rf.write_lab_record(path, timeline, truth, clock_offset_s=offset, t0_monotonic_s=getattr(lab, "t0", None))

