"""The report on files the real producers wrote: a shaker run against the virtual lab
(``labkit shaker --lab``, knee records) and a sweep from ``labkit simulate sweep``."""
from __future__ import annotations

import json

import pytest

from clihelpers import last_json, run_cli
from labkit.experiments.session import lab_instruments_toml

SHAKER_TOML = """# report test: shaker run on the virtual lab, laser on the knee, no video
[run]
robot_spot = "knee"
video_s = 0.0
on_interlock = "skip"

{instruments}
[amplifier]
gain_db = 20.0
attenuator_db = 0.0
current_limit_a = 1.0

[shaker]
payload_kg = 0.002

[grid]
freq_hz = [150.0, 240.0]
tray_amp_um = [20.0]

[tray_control]
tolerance = 0.03
max_iterations = 8
start_vpp = 0.05

[method]
settle_s = 0.05
dwell_cycles = 15

[scope]
drive_channel = 1
velocity_channel = 2

[vibrometer]
scale_mm_s_per_v = 125.0

[interlock]
tray_max_um = 60.0
"""


@pytest.mark.slow
def test_report_on_a_virtual_lab_shaker_run(tmp_path):
    cfg = tmp_path / "shaker.toml"
    cfg.write_text(SHAKER_TOML.format(instruments=lab_instruments_toml()))
    run = tmp_path / "shaker.h5"
    s = last_json(run_cli("shaker", str(cfg), "--lab", "--seed", "1", "--out", str(run), "--json", "--quiet"))
    assert s["points_ok"] == 2
    sweep = tmp_path / "sweep.h5"
    run_cli("simulate", "sweep", "shaker", "--params", "published", "--freq-hz", "100:300:5", "--amp-um", "20",
            "--draws", "2",
            "--duration-s", "0.3", "--workers", "1", "--out", str(sweep), "--json", "--quiet")
    out = tmp_path / "rep"
    r = last_json(run_cli("report", "--runs", str(run), "--sim", str(sweep), "--knee-duration-s", "0.3",
                          "--workers", "1", "--out", str(out), "--json"))
    assert r["sections"]["knee"] == "ok" and r["sections"]["agreement"] == "ok"
    details = json.loads((out / "agreement.json").read_text())["details"]
    knee = details["knee"]
    drives = sorted(k for k in knee if k.endswith("um"))
    assert [d.split("Hz")[0] for d in drives] == ["150", "240"]
    for d in drives:
        a = knee[d]
        # the virtual lab's robot is the simulator's: the knee it measures is the one simulated,
        # up to the instruments' noise and the run's own tray amplitude
        assert a["amplitude_meas_mm_s"] > 0 and 0.8 < a["amplitude_ratio"] < 1.25, a
        assert abs(a["phase_diff_deg"]) < 20 and a["correlation"] > 0.9, a
        assert a["provenance"]["measured"] == str(run)
    # both drives' leg patterns compared (measured knee record against simulated knee record)
    assert details["patterns"]["knee record"]["n"] == 2
