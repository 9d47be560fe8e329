"""One output policy for every command that writes files (labkit.outputs, docs/file-formats.md "Outputs").

Per command: (1) any one of its outputs already there -> exit 2 naming it and ``--force``, the
file untouched (SHA-256) and no work started; (2) ``--force`` replaces every output with a
complete new file; (3) ``--force`` with a writer failing mid-write (it has written part of its
file, then the disk is full) leaves every old output byte for byte and no temporary file.

The commands run in this process (``labkit.cli.main``), so a writer can be made to fail; the
run-file commands (``sweep inchip``, ``shaker``) have their own tests in tests/experiments.
"""
from __future__ import annotations

import errno
import hashlib
import shutil
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import pytest

import labkit
from clihelpers import REPO
from labkit.cli import main

SAMPLE = REPO / "sample_data"
JUNK = b"an older file that must survive\n"


@pytest.fixture(autouse=True, scope="module")
def _sample_data_is_read_only():
    """These tests read sample_data/ as inputs; none may write there."""
    before = {p.name: sha(p) for p in SAMPLE.iterdir() if p.is_file()}
    yield
    assert {p.name: sha(p) for p in SAMPLE.iterdir() if p.is_file()} == before


def sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def leftovers(folder: Path) -> list[str]:
    """Temporary files or staging folders the output policy would leave behind."""
    return sorted(p.name for p in folder.rglob("*") if ".partial" in p.name or p.name.startswith(".staging."))


@dataclass
class Case:
    """A command line, the files it writes, the writer to break and the work that must not start."""

    argv: Callable[[Path], list[str]]
    outputs: Callable[[Path], list[Path]]
    writer: tuple[str, str]                 # (module or class path, attribute): fails mid-write
    work: tuple[str, str] | None = None     # the expensive step: must not run when an output exists
    check: Callable[[Path], None] = field(default=lambda p: None)


def _opens(path: Path) -> None:
    """A replaced output is a complete file of its kind, not the junk it replaced."""
    assert path.read_bytes() != JUNK
    if path.suffix in (".h5", ".toml", ".csv", ".mkv"):
        labkit.open(path)
    elif path.suffix == ".png":
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


CASES: dict[str, Case] = {
    "simulate-shaker": Case(
        lambda d: ["simulate", "shaker", "--duration-s", "0.02", "--out", str(d / "s.h5")],
        lambda d: [d / "s.h5"], ("labkit.sim.result.SimResult", "to_h5"), ("labkit.sim", "simulate")),
    "simulate-pzt": Case(
        lambda d: ["simulate", "pzt", "--duration-s", "0.02", "--freq-hz", "438", "--voltage-v", "10",
                   "--out", str(d / "p.h5")],
        lambda d: [d / "p.h5"], ("labkit.sim.result.SimResult", "to_h5"), ("labkit.sim", "simulate")),
    "simulate-sweep": Case(
        lambda d: ["simulate", "sweep", "shaker", "--freq-hz", "200:300:2", "--draws", "1", "--duration-s", "0.02",
                   "--workers", "1", "--out", str(d / "w.h5")],
        lambda d: [d / "w.h5"], ("labkit.sim.sweep.SweepResult", "to_h5"), ("labkit.sim", "sweep")),
    "track": Case(
        lambda d: ["track", str(SAMPLE / "shaker_240hz.mkv"), "--out", str(d / "t.h5"), "--overlay", str(d / "o.mkv")],
        lambda d: [d / "t.h5", d / "t.csv", d / "t.png", d / "o.mkv"],
        ("labkit.analysis.tracking.output", "write_overlay"),        # the last writer: the others are done
        ("labkit.analysis.tracking.tracker", "track_video")),
    "calibrate": Case(
        lambda d: ["calibrate", str(SAMPLE / "shaker_240hz_track.h5"), "--amp-um", "25", "--fit", "c_r",
                   "--duration-s", "0.05", "--max-iterations", "1", "--scan", "0", "--workers", "1",
                   "--out", str(d / "cal.toml")],
        lambda d: [d / "cal.toml", d / "cal.calibration.json"],
        ("labkit.sim.params.RobotParams", "to_toml"), ("labkit.sim.calibrate", "calibrate")),
    "fit": Case(
        lambda d: ["fit", str(SAMPLE / "inchip_run.h5"), "--out", str(d / "robot.toml")],
        lambda d: [d / "robot.toml", d / "robot.fit.h5", d / "robot.fit.inchip.frf.png",
                   d / "robot.fit.inchip.stabilisation.png"],
        ("labkit.analysis.modal.plots", "plot_stabilisation"),      # the last writer
        ("labkit.analysis.modal.robot", "fit_robot")),
    "report": Case(
        lambda d: ["report", "--fit", str(SAMPLE / "robot.fit.h5"), "--runs", str(SAMPLE / "inchip_run.h5"),
                   "--no-simulate", "--out", str(d / "rep")],
        lambda d: [d / "rep" / "report.html", d / "rep" / "agreement.json", d / "rep" / "figure_data.json"],
        ("labkit.analysis.report.html", "render")),
}


def _run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    code = main(argv)
    return code, capsys.readouterr().err


def _prepare(case: Case, d: Path, which: list[Path]) -> dict[Path, str]:
    for p in which:
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(JUNK)
    return {p: sha(p) for p in which}


@pytest.mark.parametrize("name", sorted(CASES))
def test_an_existing_output_is_refused_before_any_work_and_left_untouched(name, tmp_path, capsys, monkeypatch):
    case = CASES[name]
    if case.work is not None:
        def no_work(*a, **k):
            raise AssertionError("work started although an output exists")
        monkeypatch.setattr(_resolve(case.work[0]), case.work[1], no_work)
    outputs = case.outputs(tmp_path)
    for existing in outputs:              # each output alone, sidecars included, blocks the command
        for p in outputs:
            if p.exists():
                p.unlink()
        before = _prepare(case, tmp_path, [existing])
        code, err = _run(case.argv(tmp_path), capsys)
        assert code == 2, (name, existing, err)
        assert existing.name in err and "--force" in err and "Traceback" not in err, err
        assert sha(existing) == before[existing]
        assert [p for p in outputs if p.exists()] == [existing]      # nothing else written
        assert not leftovers(tmp_path)


@pytest.mark.parametrize("name", sorted(CASES))
def test_force_replaces_every_output(name, tmp_path, capsys):
    case = CASES[name]
    outputs = case.outputs(tmp_path)
    before = _prepare(case, tmp_path, outputs)
    code, err = _run([*case.argv(tmp_path), "--force", "--quiet"], capsys)
    assert code == 0, err
    for p in outputs:
        assert sha(p) != before[p], p
        _opens(p)
    assert not leftovers(tmp_path)


@pytest.mark.parametrize("name", sorted(CASES))
def test_a_failure_mid_write_with_force_leaves_every_old_output(name, tmp_path, capsys, monkeypatch):
    case = CASES[name]
    outputs = case.outputs(tmp_path)
    before = _prepare(case, tmp_path, outputs)
    calls: list[str] = []

    def disk_full(*args, **kwargs):
        # write part of the (temporary) file the writer was given, as a real writer would, then fail
        target = next((Path(a) for a in [*args, *kwargs.values()] if isinstance(a, (str, Path))
                       and ".partial" in Path(a).name), None)
        if target is not None:
            target.write_bytes(b"partial")
        calls.append(str(target))
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(_resolve(case.writer[0]), case.writer[1], disk_full)
    with pytest.raises(OSError, match="No space left"):
        main([*case.argv(tmp_path), "--force", "--quiet"])
    capsys.readouterr()
    assert calls, "the broken writer was not reached"
    assert {p: sha(p) for p in outputs} == before
    assert not leftovers(tmp_path)


def _resolve(dotted: str) -> object:
    """A module, or a class inside one (``labkit.sim.result.SimResult``)."""
    import importlib

    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj: object = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for attr in parts[i:]:
            obj = getattr(obj, attr)
        return obj
    raise ImportError(dotted)


# --------------------------------------------------------------------------- folders

def test_missing_parent_folder_is_exit_2_before_any_work(tmp_path, capsys, monkeypatch):
    def no_work(*a, **k):
        raise AssertionError("work started")
    monkeypatch.setattr(_resolve("labkit.sim"), "simulate", no_work)
    code, err = _run(["simulate", "shaker", "--out", str(tmp_path / "missing" / "x.h5")], capsys)
    assert code == 2 and "missing" in err and "does not exist" in err
    code, err = _run(["report", "--fit", str(SAMPLE / "robot.fit.h5"), "--no-simulate",
                      "--out", str(tmp_path / "missing" / "rep")], capsys)
    assert code == 2 and "does not exist" in err
    assert not (tmp_path / "missing").exists()


def test_track_overlay_with_an_unsupported_suffix_is_exit_2(tmp_path, capsys):
    code, err = _run(["track", str(SAMPLE / "shaker_240hz.mkv"), "--overlay", str(tmp_path / "out.txt")], capsys)
    assert code == 2 and "out.txt" in err and ".mkv" in err


def test_scenario_outputs_are_checked_before_simulating(tmp_path, capsys, monkeypatch):
    import labkit.sim.scenarios as scenarios

    def no_work(*a, **k):
        raise AssertionError("work started")
    monkeypatch.setattr(scenarios, "run_scenario", no_work)
    for name in ("sim_ablations.h5", "sim_ablations.png"):
        for p in tmp_path.iterdir():
            p.unlink()
        (tmp_path / name).write_bytes(JUNK)
        code, err = _run(["simulate", "scenario", "ablations", "--quick", "--out", str(tmp_path)], capsys)
        assert code == 2 and name in err and "--force" in err
        assert (tmp_path / name).read_bytes() == JUNK


def test_demo_refuses_a_folder_it_did_not_write_and_restores_the_old_one_on_failure(tmp_path, capsys, monkeypatch):
    out = tmp_path / "demo"
    out.mkdir()
    (out / "notes.txt").write_bytes(JUNK)
    code, err = _run(["demo", "--quick", "--out", str(out)], capsys)
    assert code == 2 and "--force" in err
    code, err = _run(["demo", "--quick", "--out", str(out), "--force"], capsys)
    assert code == 2 and "labkit demo" in err                # --force replaces only a demo's own folder
    assert (out / "notes.txt").read_bytes() == JUNK
    # an earlier demo's folder: a demo failing half-way with --force puts it back, byte for byte
    from labkit.demo.run import MARKER

    (out / MARKER).write_text("written by `labkit demo`\n")
    (out / "runs").mkdir()
    (out / "runs" / "inchip.h5").write_bytes(JUNK)
    before = {p.relative_to(out): sha(p) for p in out.rglob("*") if p.is_file()}

    def half_way(out_dir, **kw):
        (Path(out_dir) / "runs").mkdir()
        (Path(out_dir) / "runs" / "inchip.h5").write_bytes(b"partial")
        raise OSError(errno.ENOSPC, "No space left on device")

    import labkit.demo.run as demo_run

    monkeypatch.setattr(demo_run, "_run_demo", half_way)
    with pytest.raises(OSError):
        main(["demo", "--quick", "--out", str(out), "--force", "--quiet"])
    assert {p.relative_to(out): sha(p) for p in out.rglob("*") if p.is_file()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demo"]        # no backup folder left


def test_sample_data_refuses_existing_samples_and_a_failure_with_force_keeps_them(tmp_path, capsys, monkeypatch):
    from labkit.demo.sampledata import OUTPUTS

    for cfg in ("inchip.toml", "shaker.toml"):
        shutil.copy(SAMPLE / cfg, tmp_path / cfg)
    (tmp_path / "robot.toml").write_bytes(JUNK)
    code, err = _run(["sample-data", "--out", str(tmp_path)], capsys)
    assert code == 2 and "robot.toml" in err and "--force" in err
    olds = _prepare(CASES["fit"], tmp_path, [tmp_path / n for n in OUTPUTS])

    import labkit.demo.run as demo_run

    def half_way(lab, cfg_path, run_path, *a, **k):
        Path(run_path).write_bytes(b"partial")
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(demo_run, "inchip_run", half_way)
    with pytest.raises(OSError):
        main(["sample-data", "--out", str(tmp_path), "--force", "--quiet"])
    assert {p: sha(p) for p in olds} == olds
    assert not leftovers(tmp_path)


def test_a_process_killed_mid_write_leaves_the_old_file(tmp_path):
    """SIGKILL (no cleanup runs) in the middle of an atomic replace: the old file is whole."""
    import signal
    import subprocess
    import sys

    target = tmp_path / "run.h5"
    target.write_bytes(JUNK)
    code = ("import sys, time\n"
            "from labkit.outputs import atomic_outputs\n"
            "with atomic_outputs([sys.argv[1], sys.argv[1] + '.csv']) as (tmp, tmp_csv):\n"
            "    tmp.write_bytes(b'new' * 1000)\n"
            "    print('writing', flush=True)\n"
            "    time.sleep(60)\n")
    proc = subprocess.Popen([sys.executable, "-c", code, str(target)], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "writing"
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        proc.kill()
    assert target.read_bytes() == JUNK
    assert not (tmp_path / "run.h5.csv").exists()
    # the partial file stays behind (nothing ran after SIGKILL), named so that it is recognisable
    assert all(".partial" in name for name in leftovers(tmp_path)) and leftovers(tmp_path)
