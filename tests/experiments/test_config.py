"""Experiment configs: the examples load; every bad value names file, key and what was expected."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from clihelpers import REPO, last_json, run_cli
from labkit.errors import ConfigError, LimitError
from labkit.experiments.config import load_inchip, load_shaker
from labkit.experiments.plans import inchip_plan, shaker_plan
from labkit.experiments.session import preflight

INCHIP = REPO / "sample_data" / "inchip.toml"
SHAKER = REPO / "sample_data" / "shaker.toml"


def edit(src: Path, dst: Path, pattern: str, repl: str) -> Path:
    text = src.read_text()
    new, n = re.subn(pattern, repl, text, count=1, flags=re.M)
    assert n == 1, pattern
    dst.write_text(new)
    return dst


def test_examples_load_and_plan():
    c = load_inchip(INCHIP)
    assert c.locations == ("body", "hip", "knee")
    assert len(c.freqs_hz) == 200 and c.freqs_hz[0] == 300.0 and abs(c.freqs_hz[-1] - 5000.0) < 1e-9
    assert np.allclose(np.diff(np.log(c.freqs_hz)), np.log(5000 / 300) / 199)
    plan = inchip_plan(c)
    assert plan.points_total == 600 and len(plan.points) == 600
    assert [s.spot for s in plan.steps if not hasattr(s, "index")] == ["body", "hip", "knee"]
    s = load_shaker(SHAKER)
    assert s.amplitude_kind == "tray_amp_um" and s.amplitudes == (10.0, 25.0)
    preflight(s)
    assert shaker_plan(s).points_total == 6


def test_resume_plan_skips_done_points():
    c = load_inchip(INCHIP)
    done = set(range(0, 205))                     # all of body and 5 of hip
    plan = inchip_plan(c, done)
    idx = [p.index for p in plan.points]
    assert idx[0] == 205 and len(idx) == 395 and not set(idx) & done
    assert plan.steps[0].spot == "hip"


@pytest.mark.parametrize("pattern, repl, key, expected", [
    (r"^amp_vpp = 4.0", "amp_vpp = 40.0", "drive.amp_vpp", "<= 20 V"),
    (r"^pzt_max_v = 20.0", "pzt_max_v = 3.0", "drive.amp_vpp", "<= 3 V"),
    (r"^spacing = \"log\"", 'spacing = "octave"', "frequencies.spacing", "'lin', 'log'"),
    (r"^count = 200", "count = 0", "frequencies.count", "an integer >= 1"),
    (r"^settle_s = 0.05", "settle_s = 0.05\nsettle_cycles = 3", "method.settle_s", "one of settle_s or settle_cycles"),
    (r"^settle_s = 0.05", "settle_cycle = 3", "method.settle_cycle", "one of"),
    (r"^kind = \"stepped\"", 'kind = "noise"', "method.kind", "'stepped', 'chirp'"),
    (r"^locations = .*$", 'locations = ["body", "elbow"]', "run.locations[1]", "names from"),
    (r"^on_interlock = \"skip\"", 'on_interlock = "pause"', "run.on_interlock", "'skip', 'end'"),
    (r"^velocity_channel = 2", "velocity_channel = 1", "scope.velocity_channel", "a different scope channel"),
    (r"^model = \"InfiniiVision\"", 'model = "TDS2000"', "instruments.scope.model", "InfiniiVision"),
    (r"^channel = 1", "chanel = 1", "instruments.funcgen.chanel", "max_amp_vpp"),
    (r"^scale_mm_s_per_v = 25.0", 'scale_mm_s_per_v = "fast"', "vibrometer.scale_mm_s_per_v", "a number"),
])
def test_bad_inchip_values(tmp_path, pattern, repl, key, expected):
    bad = edit(INCHIP, tmp_path / "bad.toml", pattern, repl)
    with pytest.raises(ConfigError) as err:
        load_inchip(bad)
    msg = str(err.value)
    assert str(bad) in msg and f"key '{key}'" in msg and expected in msg, msg


def test_missing_table_and_chirp_list(tmp_path):
    text = INCHIP.read_text()
    table = "[vibrometer]\nscale_mm_s_per_v = 25.0  # velocity decoder range\n"
    (tmp_path / "a.toml").write_text(text.replace(table, ""))
    with pytest.raises(ConfigError, match="key 'vibrometer'.*missing table"):
        load_inchip(tmp_path / "a.toml")
    chirp = re.sub(r"\[method\][^\[]*", '[method]\nkind = "chirp"\nlength_s = 0.5\naverages = 2\n\n', text)
    (tmp_path / "b.toml").write_text(chirp)
    c = load_inchip(tmp_path / "b.toml")
    assert c.method.kind == "chirp" and c.method.averages == 2
    plan = inchip_plan(c)
    assert plan.points_total == 3 and plan.points[0].spacing == "LOG"


@pytest.mark.parametrize("pattern, repl, key, expected", [
    (r"^tray_amp_um = .*$", "tray_amp_um = [10.0]\ndrive_vpp = [0.1]", "grid.tray_amp_um", "exactly one of"),
    (r"^gain_db = 20.0", "gain_db = 30.0", "amplifier.gain_db", "20 or 40"),
    (r"^tray_amp_um = .*$", "tray_amp_um = [10.0, 80.0]", "grid.tray_amp_um", "<= 60 um"),
    (r"^robot_spot = \"knee\"", 'robot_spot = "tray"', "run.robot_spot", "'body', 'hip', 'knee'"),
    (r"^video_s = 0.0", "video_s = 2.0", "instruments.camera", "an [instruments.camera] table"),
    (r"^tolerance = 0.02", "tolerance = 0.9", "tray_control.tolerance", "<= 0.5"),
])
def test_bad_shaker_values(tmp_path, pattern, repl, key, expected):
    bad = edit(SHAKER, tmp_path / "bad.toml", pattern, repl)
    with pytest.raises(ConfigError) as err:
        load_shaker(bad)
    msg = str(err.value)
    assert str(bad) in msg and f"key '{key}'" in msg and expected in msg, msg


def test_shaker_limits_checked_before_anything_opens(tmp_path):
    over_cap = edit(SHAKER, tmp_path / "cap.toml", r"^tray_amp_um = .*$", "drive_vpp = [0.5, 3.0]")
    with pytest.raises(LimitError) as err:
        preflight(load_shaker(over_cap))
    assert "grid.drive_vpp[1]" in str(err.value) and "2718 input cap" in str(err.value)
    # 4 mm stroke: 50 um is fine at 150 Hz, but at 12 Hz 3000 um passes the interlock only if allowed
    stroke = edit(SHAKER, tmp_path / "stroke.toml", r"^freq_hz = .*$", "freq_hz = [15.0, 2000.0]")
    stroke = edit(stroke, tmp_path / "stroke2.toml", r"^tray_max_um = 60.0", "tray_max_um = 100.0")
    stroke = edit(stroke, tmp_path / "stroke3.toml", r"^tray_amp_um = .*$", "tray_amp_um = [50.0]")
    with pytest.raises(LimitError) as err:
        preflight(load_shaker(stroke))
    assert err.value.limit in ("force", "velocity") and "grid.freq_hz[1]" in str(err.value)


def test_cli_bad_config_exits_2_with_file_key_expected(tmp_path):
    bad = edit(INCHIP, tmp_path / "bad.toml", r"^amp_vpp = 4.0", "amp_vpp = 50.0")
    proc = run_cli("sweep", "inchip", str(bad), "--out", str(tmp_path / "x.h5"), "--json", check=2)
    err = proc.stderr.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in proc.stderr
    assert str(bad) in err[0] and "drive.amp_vpp" in err[0] and "expected" in err[0]
    assert last_json(proc)["ok"] is False
    assert not (tmp_path / "x.h5").exists()            # nothing written, nothing opened
    proc = run_cli("shaker", str(tmp_path / "missing.toml"), "--out", str(tmp_path / "y.h5"), check=2)
    assert "missing.toml" in proc.stderr and "no such file" in proc.stderr


def test_unreachable_instrument_exits_3_and_writes_nothing(tmp_path):
    cfg = tmp_path / "c.toml"
    cfg.write_text(INCHIP.read_text().replace("192.168.1.10::5025", "127.0.0.1::1"))   # nobody listens
    out = tmp_path / "x.h5"
    proc = run_cli("sweep", "inchip", str(cfg), "--out", str(out), check=3)
    assert "funcgen" in proc.stderr and "open" in proc.stderr and "Traceback" not in proc.stderr
    assert not out.exists()
