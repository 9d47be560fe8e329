"""``labkit lab serve`` in a real subprocess: JSON line, an instrument answers, SIGINT ends it."""
from __future__ import annotations

import contextlib
import json
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import serial
from labhelpers import Raw

from tests.conftest import run_cli  # noqa: F401  (the shared helper; used below)


@contextlib.contextmanager
def _served(*args: str) -> Iterator[tuple[subprocess.Popen, dict]]:
    """``labkit lab serve --json ARGS`` in a subprocess: (process, resources); SIGINT at the end."""
    proc = subprocess.Popen([sys.executable, "-m", "labkit", "lab", "serve", "--json", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        yield proc, json.loads(proc.stdout.readline())
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()


@pytest.mark.slow
def test_serve_prints_resources_answers_and_stops_on_sigint(tmp_path):
    proc = subprocess.Popen([sys.executable, "-m", "labkit", "lab", "serve", "--json", "--seed", "5"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        resources = json.loads(line)
        assert set(resources) == {"funcgen", "scope", "vibrometer", "control"}
        fg = Raw(resources["funcgen"], 10)
        assert fg.query("*IDN?").startswith("Keysight Technologies,33522B")
        fg.write("OUTP1 ON")
        assert fg.query("OUTP1?") == "1"
        fg.close()
        with serial.Serial(resources["vibrometer"][4:-7], 115200, timeout=5) as port:
            port.write(b"Get,VeloDec,1,Range\n")
            assert port.readline() == b"125mm/s/V\n"
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 130, err
    assert "interrupted by SIGINT" in err and "Traceback" not in err
    assert json.loads(out.strip().splitlines()[-1])["exit_code"] == 130


@pytest.mark.slow
def test_serve_other_models_rigol_and_ofv3001(tmp_path):
    """Every driver has a counterpart: the Rigol pair and the OFV-3001 are picked on the command line."""
    with _served("--funcgen", "DG1062Z", "--scope", "DS1104Z", "--vibrometer", "OFV-3001") as (proc, resources):
        fg, sc = Raw(resources["funcgen"], 10), Raw(resources["scope"], 10)
        assert fg.query("*IDN?").split(",")[1] == "DG1062Z" and fg.query(":OUTP1?") == "OFF"
        assert sc.query("*IDN?").split(",")[1] == "DS1104Z" and sc.query(":SYST:ERR?") == '0,"No error"'
        fg.close()
        sc.close()
        with serial.Serial(resources["vibrometer"][4:-7], 9600, timeout=5) as port:
            port.write(b"VELO?\n")
            assert port.readline() == b"3\n"
    assert proc.returncode == 130
    proc = run_cli("lab", "serve", "--funcgen", "33600A", check=2, timeout=60)
    assert "33600A" in proc.stderr and "DG1062Z" in proc.stderr and "Traceback" not in proc.stderr


@pytest.mark.slow
def test_serve_sigterm_also_shuts_down(tmp_path):
    from labkit.lab.client import LabControl
    from labkit.sim import RobotParams

    robot = tmp_path / "robot.toml"
    RobotParams().with_modes(freq_hz=(450.0, 1200.0, 1800.0)).to_toml(robot, provenance={"by": "test"})
    proc = subprocess.Popen([sys.executable, "-m", "labkit", "lab", "serve", "--robot", str(robot),
                             "--setup", "shaker", "--spot", "hip"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        resources = json.loads(proc.stdout.readline())
        assert resources["scope"].startswith("TCPIP0::127.0.0.1::")
        with LabControl(resources["control"], timeout_s=10) as ctl:
            truth = ctl.truth()       # the robot file's hip mode is the lab's
            assert truth["tethered_modes"]["freq_hz"][0] == pytest.approx(450.0)
            assert ctl.setup() == "shaker" and ctl.spot() == "hip"
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 130 and "SIGTERM" in err


@pytest.mark.slow
def test_serve_bad_robot_file_exits_2(tmp_path):
    bad = tmp_path / "robot.toml"
    bad.write_text("mass_mg = -3\n")
    proc = run_cli("lab", "serve", "--robot", str(bad), check=2, timeout=60)
    assert "robot.toml" in proc.stderr and "mass_mg" in proc.stderr and "Traceback" not in proc.stderr
    proc = run_cli("lab", "serve", "--robot", str(tmp_path / "none.toml"), check=2, timeout=60)
    assert "none.toml" in proc.stderr


@pytest.mark.slow
@pytest.mark.parametrize("flag, form", [("--vxi11", "::inst0::INSTR"), ("--hislip", "::INSTR")])
def test_serve_vxi11_or_hislip_gives_instr_resources_in_json_config_and_record(tmp_path, flag, form):
    """``--vxi11``: the generator and the scope answer as ``TCPIP0::127.x.y.z::inst0::INSTR`` (pyvisa-py's
    VXI-11 client); ``--hislip``: as ``TCPIP0::127.0.0.1::hislip0,<port>::INSTR`` (its HiSLIP client). The
    config written uses those resources and passes labkit check; the record keeps the raw sockets too."""
    import pyvisa

    from labkit.experiments.locks import served_labs

    config = tmp_path / "lab.toml"
    with _served(flag, "--funcgen", "DG1062Z", "--scope", "DS1202Z-E", "--config", str(config)) as (proc, resources):
        assert resources["scope"].endswith(form) and resources["funcgen"].endswith(form)
        assert ("hislip0," in resources["scope"]) == (flag == "--hislip")
        assert resources["vibrometer"].startswith("ASRL") and resources["control"].endswith("::SOCKET")
        # (the resource manager is pyvisa's shared one: closing it would close every session of this process)
        sc = pyvisa.ResourceManager("@py").open_resource(resources["scope"], timeout=5000)
        try:
            assert sc.query("*IDN?").split(",")[1] == "DS1202Z-E"
        finally:
            sc.close()
        deadline = time.monotonic() + 20      # the record is written after the config (and the JSON line)
        while not [r for r in served_labs() if r["pid"] == proc.pid] and time.monotonic() < deadline:
            time.sleep(0.05)
        record = next(r for r in served_labs() if r["pid"] == proc.pid)
        text = config.read_text()
        assert resources["scope"] in text and resources["funcgen"] in text
        # the ::INSTR config as it was written, through labkit's own check (drivers, sync, trigger)
        checked = run_cli("check", str(config), check=0, timeout=120)
        assert "all checks passed" in checked.stdout + checked.stderr
        # and labkit off through the same config switches an output left on over VXI-11
        fg = pyvisa.ResourceManager("@py").open_resource(resources["funcgen"], timeout=5000)
        try:
            fg.write(":OUTP1 ON")
            assert fg.query(":OUTP1?") == "ON\n"
            off = run_cli("off", str(config), check=0, timeout=60)
            assert "confirmed" in off.stdout + off.stderr and fg.query(":OUTP1?") == "OFF\n"
        finally:
            fg.close()
        assert record["resources"]["scope"] == resources["scope"]
        assert record["sockets"]["scope"].endswith("::SOCKET")
    assert proc.returncode == 130


@pytest.mark.slow
def test_serve_vxi11_without_root_says_port_111_needs_root():
    """The same command as an unprivileged user (setpriv to nobody): port 111 cannot be bound; one line,
    exit 2, naming the port and what to do, no traceback, and no lab left behind."""
    import shutil
    import tempfile

    home = Path(tempfile.mkdtemp(prefix="labkit-nobody-"))     # pytest's tmp_path is root's alone (0700)
    try:
        home.chmod(0o777)
        env = {"PATH": "/usr/bin:/bin", "HOME": str(home), "XDG_RUNTIME_DIR": str(home),
               "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
        proc = subprocess.run(["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups", sys.executable,
                               "-m", "labkit", "lab", "serve", "--vxi11", "--config", str(home / "lab.toml")],
                              capture_output=True, text=True, timeout=120, env=env, cwd=str(home))
        assert proc.returncode == 2, proc.stderr
        lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
        assert len(lines) == 1 and "port 111" in lines[0] and "root" in lines[0] and "--vxi11" in lines[0], lines
        assert "Traceback" not in proc.stderr and not (home / "lab.toml").exists()
    finally:
        shutil.rmtree(home, ignore_errors=True)
