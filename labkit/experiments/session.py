"""One experiment session: config -> limits -> (virtual lab) -> rig -> plan -> runner -> run file.

This is what ``labkit sweep inchip`` and ``labkit shaker`` call.
"""
from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from labkit.errors import InputError
from labkit.experiments import kinds
from labkit.experiments import runfile as rf
from labkit.experiments.config import InstrumentSpec, comparable
from labkit.experiments.kinds import Config
from labkit.experiments.locks import ServedLabRecord
from labkit.experiments.plans import Plan
from labkit.experiments.runner import InterlockRecord, video_bytes, video_folder
from labkit.experiments.safety import shielded
from labkit.jsonutil import to_jsonable


class SessionSummary(rf.RunSummary, total=False):
    """:func:`run_session`'s result (the CLI's ``--json`` line): the run file's summary, and how it ended."""

    ok: bool
    interlocks: list[InterlockRecord]      # each point an interlock stopped in this session

def load(kind: str, path: str | Path) -> Config:
    """Read and validate a config of experiment ``kind`` (``"inchip"``, ``"shaker"``)."""
    return kinds.get(kind).load(path)


def preflight(cfg: Config) -> None:
    """Check every limit that needs no instrument, before anything is opened (LimitError naming file and key)."""
    kinds.preflight(cfg)


#: the models the virtual lab simulates, by role
LAB_MODELS = {"funcgen": "33500B", "scope": "InfiniiVision", "vibrometer": "OFV-5000", "control": "LabControl"}

#: placeholder resources (TEST-NET addresses, never reached): ``--lab`` replaces them
_PLACEHOLDER_RESOURCES = {"funcgen": "TCPIP0::192.0.2.1::5025::SOCKET",
                          "scope": "TCPIP0::192.0.2.2::5025::SOCKET",
                          "vibrometer": "ASRL/dev/ttyUSB0::INSTR"}


def lab_instruments_toml(roles: tuple[str, ...] = ("funcgen", "scope", "vibrometer")) -> str:
    """The ``[instruments.*]`` tables of a config meant for ``--lab``: the lab's models, placeholder resources."""
    return "\n".join(f'[instruments.{role}]\nmodel = "{LAB_MODELS[role]}"\n'
                     f'resource = "{_PLACEHOLDER_RESOURCES[role]}"\n'
                     for role in roles)


@contextlib.contextmanager
def virtual_lab(cfg: Any, seed: int = 0, lab: Any = None) -> Iterator[tuple[Any, Any]]:
    """Yield ``(lab, cfg pointed at it)``: a new in-process virtual lab, or ``lab`` (left running)."""
    import dataclasses

    from labkit.lab import VirtualLab

    with (contextlib.nullcontext(lab.start()) if lab is not None else VirtualLab(seed=seed)) as lab:
        res = dict(lab.resources)
        # the driver models of the lab's simulated instruments (a lab served as DG1062Z/DS1104Z needs
        # the Rigol drivers); the defaults only for a lab object that does not name them
        models = dict(LAB_MODELS) | dict(getattr(lab, "models", None) or {})
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
                stdin: Any = None, force: bool = False, retry_interlocked: bool = False) -> SessionSummary:
    """Run an in-chip sweep (``kind="inchip"``) or a shaker run; return the JSON summary.

    ``lab``: False (the config's instruments), True (start a virtual lab in-process for
    this run), ``"served"`` (the running ``labkit lab serve``, else as True: the CLI's
    ``--lab``), or a running :class:`labkit.lab.VirtualLab` to use.

    Order (each step only when the ones before passed): config and every limit
    (nothing opened), output paths and free space, the locks on every instrument
    and on the run file (another run's rig is never touched), the instruments
    (the generator's outputs are turned off first), the run file, the runner.

    Raises
    ------
    InputError / ConfigError / LimitError / DiskFull / RigBusy
        Bad config, paths, too little room, instruments in use (nothing was opened or sent).
    InstrumentError
        An instrument or its link failed (the drive is off).
    DriveNotOff
        The drive could not be confirmed off (exit 4): a person must act.
    KeyboardInterrupt / Interrupted
        Interrupted (the drive is off, the file is finished and readable).
    """
    from labkit.experiments.safety import signals_raise

    with signals_raise():
        return _run_session(kind, config, out, lab=lab, resume=resume, quiet=quiet, seed=seed, stdin=stdin,
                            force=force, retry_interlocked=retry_interlocked)


def _output_path(out: str | Path | None, resume: str | Path | None) -> Path:
    if resume is not None:
        if out is not None and Path(out).resolve() != Path(resume).resolve():
            raise InputError("--out and --resume name different files", key="--out",
                             expected="--resume FILE alone, or the same FILE for both")
        path = Path(resume)
        if not path.is_file():
            raise InputError("no such run file", file=path, key="--resume")
        check_writable(path.parent, "--resume")
        if not os.access(path, os.W_OK):
            raise InputError("the run file is read-only", file=path, key="--resume",
                             expected="a run file this user can append to")
        return path
    if out is None:
        raise InputError("no output file", key="--out", expected="--out FILE (or --resume FILE)")
    path = Path(out)
    if path.exists():
        raise InputError("already exists; use --resume to continue it, or another --out", file=path, key="--out")
    if not path.parent.is_dir():
        raise InputError("the folder does not exist", file=path, key="--out")
    check_writable(path.parent, "--out")
    return path


def _remove_partials(path: Path) -> None:
    """Temporary files a killed run of ``path`` left: its partial videos and run file."""
    folder = video_folder(path)
    if folder.is_dir():
        for p in folder.glob(".*.partial.mkv"):
            p.unlink(missing_ok=True)
    rf.remove_stale_partials(path)
    rf.recover_journal(path)


def _check_videos(path: Path, force: bool) -> None:
    """An earlier run's videos in ``<run>_videos`` are refused (exit 2) unless ``--force``."""
    from labkit.outputs import check_output_dir

    folder = video_folder(path)
    if folder.is_dir():
        names = sorted(p.name for p in folder.iterdir() if p.suffix.lower() == ".mkv")
        check_output_dir(folder, force=force, key="--out", names=names)


def check_writable(folder: Path, key: str) -> None:
    """InputError unless a file can be created in ``folder`` (tried, not guessed: root ignores modes)."""
    import tempfile

    try:
        fd, probe = tempfile.mkstemp(prefix=".labkit-probe.", dir=folder)
    except OSError as exc:
        raise InputError(f"cannot write in this folder ({exc.strerror or exc})", file=folder, key=key,
                         expected="a folder this user can create files in") from None
    os.close(fd)
    os.unlink(probe)


def _run_session(kind: str, config: str | Path, out: str | Path | None, *, lab: Any, resume: str | Path | None,
                 quiet: bool, seed: int, stdin: Any, force: bool = False,
                 retry_interlocked: bool = False) -> SessionSummary:
    from labkit.experiments.locks import lock_run

    experiment = kinds.get(kind)
    if lab == "served":
        lab = served_or_new()
    cfg = experiment.load(config)
    experiment.preflight(cfg)
    path = _output_path(out, resume)
    video_s = float(getattr(cfg, "video_s", 0.0) or 0.0)
    if video_s > 0 and resume is None:
        _check_videos(path, force)
    stack = contextlib.ExitStack()
    with stack:
        lab_obj = None
        if lab is not False and lab is not None:
            lab_obj, cfg = stack.enter_context(virtual_lab(cfg, seed=seed, lab=None if lab is True else lab))
        # one rig, one run: every instrument and the run file locked before anything is opened
        stack.enter_context(lock_run(((r, s.resource) for r, s in cfg.instruments.items()), path, str(cfg.path)))
        _remove_partials(path)          # left by a run of this file that was killed (we hold its lock)
        cfg_json = comparable(cfg)
        n_left = experiment.plan(cfg, ()).points_total
        if resume is not None:
            rf.check_room(path, rf.RESERVE_BYTES, key="--resume")       # resuming writes a little at once
        if retry_interlocked and resume is None:
            raise InputError("--retry-interlocked continues a run file", key="--retry-interlocked",
                             expected="--resume FILE as well")
        journal = 2 * experiment.point_bytes(cfg) + rf.RESERVE_BYTES     # one flush: a point and its metadata
        run = (rf.RunFile.resume(path, cfg, cfg_json, retry_interlocked=retry_interlocked,   # checks the config
                                 journal_bytes=journal) if resume is not None else None)
        if run is not None:
            n_left = len(experiment.plan(cfg, run.done).points)
        # the whole run must fit (HDF5 cannot survive a full disk); nothing opened yet if not
        need = (0 if run is not None else rf.BASE_BYTES) + n_left * experiment.point_bytes(cfg)
        rf.check_room(path, need + n_left * video_bytes(video_s), key="--resume" if run is not None else "--out")
        # set aside for the file: a disk that fills up meanwhile cannot take it (two points and the
        # reserve more than the estimate, so the last point's room check passes)
        reserve = need + 2 * experiment.point_bytes(cfg) + rf.RESERVE_BYTES
        if run is not None:
            run.reserve(reserve)
        runner = None
        try:
            from labkit.experiments.rig import PromptSpot, Rig
            from labkit.experiments.runner import Runner

            # a given stdin means a person answers the prompts (even with a lab control channel)
            spot = PromptSpot(stdin=stdin) if stdin is not None else None
            # instruments first (the drive stays off): a rig that cannot be opened leaves no new file
            rig = stack.enter_context(Rig(cfg, spot=spot))
            if run is None:
                run = rf.RunFile.create(path, cfg, cfg_json, experiment.plan(cfg, ()).points_total,
                                        reserve_bytes=reserve, journal_bytes=journal)
            plan: Plan = experiment.plan(cfg, run.done)
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
                with shielded(), contextlib.suppress(Exception):
                    run.event(f"run not started: {why}")
                    run.finish(why)
            raise
        finally:
            with shielded():
                if run is not None:
                    run.close()
                    if lab_obj is not None and rf.headroom_bytes(path) > rf.RESERVE_BYTES / 2:
                        _store_lab_record(path, lab_obj)
                    rf.release_space(path)          # what the run did not use
    out_summary: SessionSummary = {**rf.summary(path), "ok": True, "status": status}
    if runner is not None:
        out_summary["interlocks"] = runner.interlocks
    return out_summary


class ServedLab:
    """A virtual lab another process serves (``labkit lab serve``): used, never started or closed here."""

    def __init__(self, record: ServedLabRecord) -> None:
        self.resources: dict[str, str] = dict(record["resources"])
        self.models: dict[str, str] = dict(record.get("models") or {})
        self.pid = record.get("pid")

    def start(self) -> ServedLab:
        return self


def served_or_new() -> ServedLab | bool:
    """``--lab``: the newest running ``labkit lab serve`` if there is one, else True (start one in-process)."""
    from labkit.experiments.locks import served_labs

    labs = served_labs()
    return ServedLab(labs[0]) if labs else True


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

