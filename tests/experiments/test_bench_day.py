"""A bench day on the virtual lab: devices, identify, init, check, and served labs' records.

Real processes throughout (``labkit lab serve``, ``labkit init``/``check``/``sweep``), each
with its own runtime folder (``XDG_RUNTIME_DIR``) so parallel test runs never see each
other's served labs.
"""
from __future__ import annotations

import contextlib
import json
import math
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from labkit.lab import VirtualLab

REPO = Path(__file__).resolve().parents[2]


def _env(runtime: Path) -> dict[str, str]:
    runtime.mkdir(exist_ok=True)
    return dict(os.environ, PYTHONUNBUFFERED="1", XDG_RUNTIME_DIR=str(runtime))


def _labkit(env: dict[str, str], *args: str, check: int | None = 0, timeout: float = 300,
            cwd: Path | None = None) -> subprocess.CompletedProcess:
    proc = subprocess.run([sys.executable, "-m", "labkit", *args], env=env, capture_output=True, text=True,
                          timeout=timeout, cwd=cwd or REPO)
    if check is not None:
        assert proc.returncode == check, (f"labkit {' '.join(args)} exited {proc.returncode}, expected {check}\n"
                                          f"stdout:\n{proc.stdout[-4000:]}\nstderr:\n{proc.stderr[-3000:]}")
    return proc


@contextlib.contextmanager
def served(env: dict[str, str], *args: str):
    """``labkit lab serve ARGS`` in a real process; yields (resources, its record)."""
    proc = subprocess.Popen([sys.executable, "-m", "labkit", "lab", "serve", *args], env=env, cwd=REPO,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        assert line.startswith("{"), f"lab serve: {line!r} {proc.poll()}"
        resources = json.loads(line)
        record = Path(env["XDG_RUNTIME_DIR"]) / "labkit" / f"lab-serve-{proc.pid}.json"
        for _ in range(600):               # the record follows the resources line
            if record.is_file() and record.stat().st_size:
                break
            assert proc.poll() is None
            import time
            time.sleep(0.05)
        yield resources, json.loads(record.read_text()), proc
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
        with contextlib.suppress(subprocess.TimeoutExpired):
            proc.communicate(timeout=30)
        if proc.poll() is None:
            proc.kill()
            proc.communicate()


class Raw:
    """A bare SCPI socket client (no pyvisa, no labkit driver)."""

    def __init__(self, resource: str, timeout_s: float = 10.0) -> None:
        import socket

        _, host, port, _ = resource.split("::")
        self.file = socket.create_connection((host, int(port)), timeout=timeout_s).makefile("rwb")

    def write(self, text: str) -> None:
        self.file.write(text.encode() + b"\n")
        self.file.flush()

    def query(self, text: str) -> str:
        self.write(text)
        return self.file.readline().decode().strip()

    def close(self) -> None:
        self.file.close()


def _docs_block(marker: str) -> dict[str, str]:
    """Check names and verdicts of the text block in docs/bench-day.md that holds ``marker``."""
    blocks = re.findall(r"```text\n(.*?)```", (REPO / "docs" / "bench-day.md").read_text(), re.DOTALL)
    found = [b for b in blocks if marker in b]
    assert len(found) == 1, marker
    return _lines(found[0])


def _lines(text: str) -> dict[str, str]:
    """``check``'s output: check name -> status."""
    out = {}
    for m in re.finditer(r"^(PASS|WARN|FAIL)  ([^:]+):", text, re.MULTILINE):
        out[m.group(2)] = m.group(1)
    return out


# ----------------------------------------------------------------------------- library pieces

def test_fit_sine_recovers_a_known_sine():
    """Amplitude, phase and a frequency 0.05 % off the fit's, from a record with noise (closed form)."""
    from labkit.experiments.bench import fit_sine

    rng = np.random.default_rng(1)
    f_true, f_fit = 1000.5, 1000.0
    t = np.arange(20000) / 1e6
    v = 0.7 * np.sin(2 * np.pi * f_true * t + math.radians(30.0)) + 0.2 + rng.normal(0, 1e-3, t.size)
    s = fit_sine(t, v, f_fit)
    assert s.amp_vpp == pytest.approx(1.4, rel=2e-3)
    assert s.freq_hz == pytest.approx(f_true, rel=2e-5)
    # over the record the phase drifts by 2 pi (f_true - f_fit) t; at its middle (10 ms) 1.8 deg
    assert s.phase_deg == pytest.approx(30.0 + 360 * 0.5 * 0.01, abs=0.5)


def test_templates_hold_every_key_and_load_once_the_todos_are_filled(tmp_path):
    from labkit.experiments.config import load_inchip, load_shaker
    from labkit.experiments.template import Band, Instrument, Wiring, inchip_text, shaker_text, todo_keys

    inst = {"funcgen": Instrument("33500B", "TCPIP0::192.0.2.1::5025::SOCKET"),
            "scope": Instrument("InfiniiVision", "TCPIP0::192.0.2.2::5025::SOCKET"),
            "vibrometer": Instrument("OFV-5000", "ASRL/dev/ttyUSB0::INSTR")}
    text = inchip_text(inst, Wiring(), band=Band(300, 5000, 5))
    # the keys labkit.experiments.config accepts in each in-chip table (stepped method)
    for key in ("locations", "on_interlock", "amp_vpp", "offset_v", "pzt_max_v", "start_hz", "stop_hz", "count",
                "spacing", "kind", "settle_s", "dwell_cycles", "keep_raw", "drive_channel", "velocity_channel",
                "trigger_source", "samples_per_cycle", "max_points", "drive_volts_per_div",
                "velocity_volts_per_div", "scale_mm_s_per_v", "timeout_s", "channel"):
        assert re.search(rf"^#? ?{key} = ", text, re.MULTILINE), key
    cfg = tmp_path / "in.toml"
    cfg.write_text(text)
    assert todo_keys(cfg) == ["scope.drive_channel", "scope.velocity_channel", "vibrometer.scale_mm_s_per_v"]
    with pytest.raises(Exception, match="drive_channel"):
        load_inchip(cfg)
    filled = (text.replace('drive_channel = "TODO"', "drive_channel = 1")
              .replace('velocity_channel = "TODO"', "velocity_channel = 2")
              .replace('scale_mm_s_per_v = "TODO"', "scale_mm_s_per_v = 25"))
    cfg.write_text(filled)
    assert todo_keys(cfg) == [] and load_inchip(cfg).freqs_hz[-1] == pytest.approx(5000.0)

    # every driver setting the template lists is one its driver accepts (uncommented, the config loads)
    for models in (("33220A", "InfiniiVision", "OFV-3001"), ("DG1000Z", "DS1000Z", "OFV-5000")):
        inst2 = {r: Instrument(m, i.resource) for (r, i), m in zip(inst.items(), models)}
        text2 = inchip_text(inst2, Wiring(1, 2, 25.0))
        head, tail = text2.split("[drive]")
        settings = re.findall(r"^# (\w+) = ", head, re.MULTILINE)
        assert len(settings) >= 8 and "max_amp_vpp" in settings and "baud_rate" in settings
        cfg.write_text(re.sub(r"^# (\w+ = )", r"\1", head, flags=re.MULTILINE) + "[drive]" + tail)
        loaded = load_inchip(cfg)
        assert sum(len(s.settings) for s in loaded.instruments.values()) >= len(settings) - 1
    sh = tmp_path / "sh.toml"
    sh.write_text(shaker_text(inst, Wiring()))
    assert set(todo_keys(sh)) == {"amplifier.gain_db", "shaker.accel_m_s2_per_v", "scope.drive_channel",
                                  "scope.velocity_channel", "vibrometer.scale_mm_s_per_v"}
    sh.write_text(shaker_text(inst, Wiring(1, 2, 125.0, 20.0, 20.0)))
    assert load_shaker(sh).accel_m_s2_per_v == 20.0


# ----------------------------------------------------------------------------- devices, identify

def _announce(lab: VirtualLab, runtime: Path, monkeypatch) -> None:
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(runtime))
    from labkit.experiments.locks import announce_lab

    announce_lab(lab.resources, lab.models)


def test_devices_lists_each_backend_and_the_lab_and_sends_nothing(tmp_path, monkeypatch):
    env = _env(tmp_path / "rt")
    with VirtualLab(seed=3) as lab:
        _announce(lab, tmp_path / "rt", monkeypatch)
        out = json.loads(_labkit(env, "devices", "--json").stdout.strip().splitlines()[-1])
        text = _labkit(env, "devices").stdout
        received = [e for e in lab.log if e[2] == "rx"]
    names = {b["name"]: b for b in out["backends"]}
    assert {"pyvisa-py USB INSTR", "pyvisa-py TCPIP INSTR", "pyvisa-py GPIB INSTR", "pyvisa-py ASRL INSTR",
            "pyvisa-py TCPIP SOCKET", "pyserial", "virtual labs"} <= set(names)
    for b in names.values():     # every back-end says what it lists, and why it cannot
        assert b["note"] and (b["can_list"] or "cannot" in b["note"]), b
    assert "cannot be discovered" in names["pyvisa-py TCPIP SOCKET"]["note"]
    assert sorted(names["virtual labs"]["resources"]) == sorted(f"{r}: {v}" for r, v in lab.resources.items())
    assert received == []          # nothing was sent to any instrument
    assert text.count("\n+ ") + text.count("\n- ") + (text[:2] in ("+ ", "- ")) == len(names)


@pytest.mark.parametrize("models", [("33522B", "DSOX3024T", "OFV-5000"), ("DG1062Z", "DS1104Z", "OFV-3001"),
                                    ("33220A", "DS1054Z", "OFV-5000")])
def test_identify_all_names_every_lab_instrument_and_drains_the_error_queue(tmp_path, monkeypatch, models):
    env = _env(tmp_path / "rt")
    with VirtualLab(seed=3, funcgen_model=models[0], scope_model=models[1], vibrometer_model=models[2]) as lab:
        _announce(lab, tmp_path / "rt", monkeypatch)
        fg = Raw(lab.resources["funcgen"], 10)
        fg.write("NOT:A:COMMAND")                     # an error left in the generator's queue
        fg.close()
        out = json.loads(_labkit(env, "identify", "--all", "--json").stdout.strip().splitlines()[-1])
        by_res = {i["resource"]: i for i in out["instruments"]}
        after = Raw(lab.resources["funcgen"], 10)
        left = after.query(":SYST:ERR?" if models[0].startswith("DG") else "SYST:ERR?")
        after.close()
    assert {by_res[lab.resources[r]]["driver"] for r in ("funcgen", "scope", "vibrometer")} == set(lab.models.values())
    fg_id = by_res[lab.resources["funcgen"]]
    assert models[0] in fg_id["reply"] and fg_id["errors"] and fg_id["errors"][0].startswith("-113")
    assert left.lstrip("+").startswith("0")                # drained
    assert by_res[lab.resources["vibrometer"]]["query"] != "*IDN?"     # the Polytec query answered


def test_identify_unreachable_and_unknown_give_hints_and_no_driver(tmp_path):
    import socket

    env = _env(tmp_path / "rt")
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()                                        # nothing listens there now
    with VirtualLab(seed=3) as lab:
        out = json.loads(_labkit(env, "identify", f"TCPIP0::127.0.0.1::{port}::SOCKET", lab.resources["control"],
                                 "--json").stdout.strip().splitlines()[-1])
    dead, control = out["instruments"]
    assert not dead["ok"] and "nothing listens" in dead["hint"]
    assert control["ok"] and control["driver"] == "no driver" and "VirtualLab" in control["reply"]
    proc = _labkit(env, "identify", check=2)
    assert "no resource to identify" in proc.stderr and "Traceback" not in proc.stderr


# ----------------------------------------------------------------------------- served labs

def test_two_served_labs_keep_their_records_and_off_lab_reaches_both(tmp_path):
    from labkit.drivers.registry import open_instrument

    env = _env(tmp_path / "rt")
    with served(env, "--json") as (res1, rec1, p1), served(env, "--json", "--funcgen", "DG1062Z") as (res2, rec2, p2):
        assert rec1["pid"] == p1.pid and rec2["pid"] == p2.pid and rec1["resources"] == res1
        gens = []
        for res, model in ((res1, "33500B"), (res2, "DG1000Z")):
            fg = open_instrument(model, res["funcgen"], name="funcgen")
            fg.set_sine(200.0, 1.0)
            fg.output(True)
            gens.append(fg)
        off = _labkit(env, "off", "--lab", "--json")
        summary = json.loads(off.stdout.strip().splitlines()[-1])
        assert {s["resource"] for s in summary["labs"]} == {res1["funcgen"], res2["funcgen"]}
        assert [fg.output_on for fg in gens] == [False, False]
        for fg in gens:
            fg.close()
        p1.send_signal(signal.SIGTERM)
        p1.communicate(timeout=30)
        # the first lab's end removed its record only: the second is still found
        left = sorted((Path(env["XDG_RUNTIME_DIR"]) / "labkit").glob("lab-serve-*.json"))
        assert [json.loads(p.read_text())["pid"] for p in left] == [p2.pid]
        assert Path(rec2["config"]).is_file() and not Path(rec1["config"]).exists()


def test_init_check_sweep_on_a_served_lab_editing_only_the_todos(tmp_path):
    env = _env(tmp_path / "rt")
    cfg = tmp_path / "bench.toml"
    with served(env) as (res, rec, _):
        out = _labkit(env, "init", "--lab", "--count", "3", "--start-hz", "400", "--stop-hz", "3000",
                      "--out", str(cfg))
        assert f"next: labkit check {cfg}" in out.stdout
        text = cfg.read_text()
        assert text.rstrip().splitlines()[-2:] == [f"#   labkit check {cfg}",
                                                    f"# then the run:  labkit sweep inchip {cfg} --out run.h5"]
        assert res["funcgen"] in text and res["control"] in text and "identifies as" in text
        early = _labkit(env, "check", str(cfg), check=2)
        assert "still TODO: scope.drive_channel, scope.velocity_channel, vibrometer.scale_mm_s_per_v" in early.stderr
        # the person edits the three TODO lines, nothing else
        edited = (text.replace('drive_channel = "TODO"', "drive_channel = 1")
                  .replace('velocity_channel = "TODO"', "velocity_channel = 2")
                  .replace('scale_mm_s_per_v = "TODO"', "scale_mm_s_per_v = 25.0"))
        changed = [(a, b) for a, b in zip(text.splitlines(), edited.splitlines()) if a != b]
        assert len(changed) == 3 and all("TODO" in a for a, _ in changed)
        cfg.write_text(edited)
        chk = _labkit(env, "check", str(cfg))
        lines = _lines(chk.stdout)
        assert "FAIL" not in lines.values() and lines["triggered acquisition"] == "PASS"
        assert lines["output off"] == "PASS" and "all checks passed" in chk.stdout
        assert lines == _docs_block("all checks passed")       # docs/bench-day.md shows this very check
        run = _labkit(env, "sweep", "inchip", str(cfg), "--out", str(tmp_path / "run.h5"), "--quiet", "--json")
        summary = json.loads(run.stdout.strip().splitlines()[-1])
        assert summary["points_ok"] == summary["points_planned"] == 9
    with h5py.File(tmp_path / "run.h5", "r") as f:
        assert f["instruments/funcgen"].attrs["resource"] == res["funcgen"]


def test_lab_flag_uses_the_served_lab(tmp_path):
    """``sweep --lab`` with a config of placeholder resources runs on the served lab (its ports)."""
    from clihelpers import stepped_inchip_toml
    from labkit.experiments.session import lab_instruments_toml

    env = _env(tmp_path / "rt")
    cfg = tmp_path / "c.toml"
    cfg.write_text(stepped_inchip_toml(lab_instruments_toml(), [500.0, 900.0]))
    with served(env) as (res, _, _):
        _labkit(env, "sweep", "inchip", str(cfg), "--lab", "--out", str(tmp_path / "r.h5"), "--quiet")
        chk = _labkit(env, "check", str(cfg), "--lab", "--json")
        report = json.loads(chk.stdout.strip().splitlines()[-1])
        assert report["ok"] and any(res["funcgen"] in c["expected"] for c in report["checks"])
    with h5py.File(tmp_path / "r.h5", "r") as f:
        assert {r: f[f"instruments/{r}"].attrs["resource"] for r in ("funcgen", "scope", "vibrometer")} == {
            r: res[r] for r in ("funcgen", "scope", "vibrometer")}


# ----------------------------------------------------------------------------- check on miswired labs

MISWIRES = {
    "swapped-channels": (["--miswire", "swapped-channels"], "drive amplitude (scope channel 1)",
                         "the channels are swapped"),
    "no-sync": (["--miswire", "no-sync"], "triggered acquisition", "SYNC output cabled to the scope's EXT TRIG"),
    "vibrometer-range": (["--miswire", "vibrometer-range-locked"], "vibrometer range",
                         "the decoder stays at 1000 mm/s/V"),
    "amplifier-gain": (["--setup", "shaker", "--amplifier-gain-db", "40"], "amplifier gain",
                       "gain switch at 20 dB"),
}


@pytest.mark.parametrize("fault", [None, *MISWIRES])
def test_check_passes_a_good_lab_and_fails_each_miswiring_by_name(tmp_path, fault):
    env = _env(tmp_path / "rt")
    args, name, why = MISWIRES[fault] if fault else (["--setup", "shaker"], "", "")
    with served(env, *args) as (_, rec, _):
        proc = _labkit(env, "check", rec["config"], check=None)
    lines = _lines(proc.stdout)
    assert "Traceback" not in proc.stderr
    assert lines["output off"] == "PASS" and lines["identity funcgen"] == "PASS"
    if fault is None:
        assert proc.returncode == 0, proc.stdout
        assert set(lines.values()) == {"PASS"} and lines["amplifier gain"] == "PASS"
        return
    assert proc.returncode == 1, proc.stdout
    # the docs page shows each fault's check failing as it does here
    shown = _docs_block("--amplifier-gain-db 40" if fault == "amplifier-gain" else f"--miswire {args[1]}")
    assert {k for k, v in shown.items() if v == "FAIL"} == {k for k, v in lines.items() if v == "FAIL"}
    assert lines[name] == "FAIL" and why in proc.stdout and "check(s) FAILED" in proc.stderr
    others = {k for k, v in lines.items() if v == "FAIL"} - {name}
    related = {"swapped-channels": {"drive frequency", "drive phase at the trigger",
                                    "velocity channel (scope channel 2)"},
               "no-sync": {"drive phase at the trigger"}}.get(fault, set())
    assert others <= related, others       # the fault is named, not buried among unrelated ones


def test_check_bad_input_exits_2_and_sends_nothing(tmp_path, monkeypatch):
    env = _env(tmp_path / "rt")
    from labkit.experiments.template import lab_config_text

    with VirtualLab(seed=1) as lab:
        cfg = tmp_path / "c.toml"
        cfg.write_text(lab_config_text("inchip", lab.resources, lab.models).replace("amp_vpp = 4.0", "amp_vpp = 30.0"))
        proc = _labkit(env, "check", str(cfg), check=2)
        assert "amp_vpp" in proc.stderr and "Traceback" not in proc.stderr
        proc = _labkit(env, "check", str(tmp_path / "none.toml"), check=2)
        assert "none.toml" in proc.stderr
        cfg.write_text(lab_config_text("inchip", lab.resources, lab.models))
        from labkit.experiments.locks import lock_run

        # a run holds the rig: check touches nothing of it
        monkeypatch.setenv("XDG_RUNTIME_DIR", env["XDG_RUNTIME_DIR"])
        with lock_run([("scope", lab.resources["scope"])], tmp_path / "busy.h5", str(cfg)):
            proc = _labkit(env, "check", str(cfg), check=2)
        assert "in use by another run" in proc.stderr and "busy.h5" in proc.stderr
        assert [e for e in lab.log if e[2] == "rx"] == []


@pytest.mark.parametrize("models", [("DG1062Z", "DS1104Z", "OFV-3001"), ("33220A", "DS1054Z", "OFV-5000")])
def test_check_passes_the_other_lab_models(tmp_path, monkeypatch, models):
    """The Rigol pair (8-bit records: the velocity channel is narrowed), the 33220A, the OFV-3001."""
    from labkit.experiments.bench import run_check
    from labkit.experiments.template import lab_config_text

    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path))
    with VirtualLab(seed=2, funcgen_model=models[0], scope_model=models[1], vibrometer_model=models[2]) as lab:
        cfg = tmp_path / "c.toml"
        cfg.write_text(lab_config_text("inchip", lab.resources, lab.models))
        report = run_check(cfg, lab=lab)
        on_after = lab.output_state("funcgen", 1)
    status = {line.name: line.status for line in report.lines}
    assert report.ok and set(status.values()) == {"PASS"}, [line.text() for line in report.lines]
    assert on_after is False


def test_init_from_resources_writes_a_shaker_config_with_its_todos(tmp_path):
    env = _env(tmp_path / "rt")
    out = tmp_path / "shaker.toml"
    with VirtualLab(seed=1, funcgen_model="DG1062Z", scope_model="DS1104Z", vibrometer_model="OFV-3001") as lab:
        res = [lab.resources[r] for r in ("vibrometer", "scope", "funcgen")]
        proc = _labkit(env, "init", *res, "--kind", "shaker", "--out", str(out), "--json")
        again = _labkit(env, "init", *res, "--out", str(out), check=2)       # never over a file
    summary = json.loads(proc.stdout.strip().splitlines()[-1])
    assert summary["instruments"] == {"funcgen": f"DG1000Z at {lab.resources['funcgen']}",
                                      "scope": f"DS1000Z at {lab.resources['scope']}",
                                      "vibrometer": f"OFV-3001 at {lab.resources['vibrometer']}"}
    assert set(summary["todo"]) == {"amplifier.gain_db", "shaker.accel_m_s2_per_v", "scope.drive_channel",
                                    "scope.velocity_channel", "vibrometer.scale_mm_s_per_v"}
    assert "already exists" in again.stderr and "--force" in again.stderr
    # no instrument found for a role: its model and resource are TODOs too
    with VirtualLab(seed=1) as lab:
        proc = _labkit(env, "init", lab.resources["scope"], "--out", str(tmp_path / "one.toml"), "--json")
    todo = json.loads(proc.stdout.strip().splitlines()[-1])["todo"]
    assert {"instruments.funcgen.model", "instruments.funcgen.resource", "instruments.vibrometer.resource"} <= set(todo)


def test_check_fails_over_range_on_a_too_sensitive_range(tmp_path, monkeypatch):
    from labkit.experiments.bench import run_check
    from labkit.experiments.template import lab_config_text

    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path))
    with VirtualLab(seed=2) as lab:
        cfg = tmp_path / "s.toml"
        text = lab_config_text("shaker", lab.resources, lab.models)
        # 1 mm/s/V is +-10 mm/s full scale; 0.2 Vpp moves the tray about 15 mm/s at 212 Hz
        cfg.write_text(text.replace("scale_mm_s_per_v = 25.0", "scale_mm_s_per_v = 1.0")
                       .replace("start_vpp = 0.05", "start_vpp = 0.2"))
        report = run_check(cfg, lab=lab)
    status = {line.name: line for line in report.lines}
    assert not report.ok and status["vibrometer over-range"].status == "FAIL"
    assert "a larger range" in status["vibrometer over-range"].todo
    assert status["output off"].status == "PASS"


@pytest.mark.parametrize("exc, words", [
    (PermissionError(13, "Permission denied"), "dialout"),
    (OSError("could not open port /dev/ttyUSB0: [Errno 13] Permission denied: '/dev/ttyUSB0'"), "udev"),
    (ValueError("Please install PyUSB to use this resource type. No module named 'usb'"), "libusb"),
    (OSError("[Errno 111] Connection refused"), "nothing listens"),
    (OSError("could not open port /dev/ttyUSB9: [Errno 2] No such file or directory"), "labkit devices"),
    (TimeoutError("timeout after 0.5 s (partial reply b'')"), "baud rate"),
])
def test_identify_hints_for_the_usual_failures(exc, words):
    """pyserial's and pyvisa-py's own messages for the usual failures, turned into what to do."""
    from labkit.experiments.discovery import _hint

    assert words in _hint("ASRL/dev/ttyUSB0::INSTR" if "usb" not in str(exc).lower() or "ttyUSB" in str(exc)
                          else "USB0::0x0957::0x2807::MY5740::INSTR", exc)


def test_lab_serve_config_option_keeps_the_file_and_never_overwrites(tmp_path):
    env = _env(tmp_path / "rt")
    cfg = tmp_path / "lab.toml"
    with served(env, "--config", str(cfg), "--setup", "shaker") as (res, rec, _):
        assert rec["config"] == str(cfg.resolve()) and res["control"] in cfg.read_text()
        from labkit.experiments.config import load_shaker

        assert load_shaker(cfg).instruments["funcgen"].resource == res["funcgen"]   # usable as is
    assert cfg.is_file()                       # the person's file stays after the lab stops
    proc = _labkit(env, "lab", "serve", "--config", str(cfg), check=2, timeout=120)
    assert "already exists" in proc.stderr and "--force" in proc.stderr and "Traceback" not in proc.stderr
