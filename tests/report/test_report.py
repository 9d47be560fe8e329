"""labkit report end to end on files in the agreed layouts (no simulator needed: --no-simulate)."""
from __future__ import annotations

import json
import re
from pathlib import Path

import h5py
import numpy as np
import pytest

from clihelpers import last_json, run_cli
from report_data import SHAKER_SPEED


def _all_inputs(inputs):
    tracks = [str(inputs[f"track{i}"]) for i in range(5)]
    return ["--runs", str(inputs["inchip"]), str(inputs["shaker"]), "--tracks", *tracks,
            "--fit", str(inputs["fit"]), "--sim", str(inputs["sweep"]), str(inputs["sim_200"]),
            str(inputs["sim_300"]), "--no-simulate"]


@pytest.mark.slow
def test_full_report_is_self_contained_and_numbers_agree(inputs, tmp_path):
    out = tmp_path / "rep"
    proc = run_cli("report", *_all_inputs(inputs), "--out", str(out), "--json")
    summary = last_json(proc)
    assert summary["sections"] == {"frf": "ok", "stabilisation": "ok", "speed": "ok", "knee": "ok",
                                   "agreement": "ok"}
    html = (out / "report.html").read_text()
    # self-contained: no external URL, no script, every image inline
    assert not re.search(r"(src|href)\s*=\s*\"(https?:|//|file:)", html)
    assert "<script" not in html.lower() and "<link" not in html.lower()
    imgs = re.findall(r"<img [^>]*src=\"([^\"]+)\"", html)
    assert len(imgs) == len(summary["figures"]) == 7   # frf + stab for 2 fit groups, speed, 2 knee drives
    assert all(s.startswith("data:image/png;base64,") for s in imgs)
    for fig in summary["figures"]:
        assert Path(fig).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # speed agreement against the sweep: measured 3.0, 4.2, 2.5, 2.9, 0.0 at 150..600 Hz;
    # simulated mean 3.5, 5.0, 3.0, 3.5, and 0.5 + (0 - 0.5) * 200/400 = 0.25 at 600 Hz
    err = np.array([0.5, 0.8, 0.5, 0.6, 0.25])
    agreement = {r["quantity"]: r["value"] for r in summary["agreement"]}
    assert agreement["speed RMS error"] == pytest.approx(np.sqrt(np.mean(err ** 2)), rel=1e-9)
    assert summary["speed_rms_error_mm_s"] == pytest.approx(np.sqrt(np.mean(err ** 2)), rel=1e-9)
    # the nominal robot (draw 0 = 0.9 x base): 3.15, 4.5, 2.7, 3.15, 0.225 at 150..600 Hz
    err_nominal = np.array([3.15, 4.5, 2.7, 3.15, 0.225]) - np.array([3.0, 4.2, 2.5, 2.9, 0.0])
    assert agreement["speed RMS error (nominal robot)"] == pytest.approx(np.sqrt(np.mean(err_nominal ** 2)))
    # knee: 200 Hz measured firm (1.05 x tray), simulated firm (1.1 x tray) -> ratio 1.1/1.05, in phase
    assert agreement["knee amplitude ratio (sim/meas) @ 200 Hz, 25 um"] == pytest.approx(1.1 / 1.05, rel=1e-3)
    assert abs(agreement["knee phase difference (sim - meas) @ 200 Hz, 25 um"]) < 1.0
    assert agreement["leg-pattern agreement (knee records)"] == pytest.approx(1.0)   # firm/firm, jumping/jumping
    # the sweep says partial contact at 200 and 300 Hz; the knee records say firm and jumping
    assert agreement["leg-pattern agreement (sweep)"] == pytest.approx(0.0)
    # every number has its provenance, naming the files
    data = json.loads((out / "agreement.json").read_text())
    for row in data["agreement"]:
        assert row["provenance"], row
    speed_row = next(r for r in data["agreement"] if r["quantity"] == "speed RMS error")
    assert str(inputs["sweep"]) == speed_row["provenance"]["simulated"]
    assert any("track0.h5" in s for s in speed_row["provenance"]["measured"])
    assert "track0.h5" in html and "sweep.h5" in html


def test_missing_inputs_are_reported_not_fatal(inputs, tmp_path):
    out = tmp_path / "rep"
    proc = run_cli("report", "--tracks", str(inputs["track4"]), "--out", str(out), "--json")
    s = last_json(proc)
    assert s["sections"]["frf"] == "missing" and "--fit" in s["missing"]["frf"]
    assert s["sections"]["stabilisation"] == "missing"
    assert s["sections"]["speed"] == "ok"                     # measured point alone is drawn
    assert s["sections"]["agreement"] == "missing"
    html = (out / "report.html").read_text()
    assert "No fit given" in html and "Nothing to compare" in html
    # an in-chip run alone: its measured FRFs are drawn, without a model curve
    proc = run_cli("report", "--runs", str(inputs["inchip"]), "--out", str(tmp_path / "rep2"), "--json")
    s = last_json(proc)
    assert s["sections"]["frf"] == "ok" and "no model curve" in s["notes"]["frf"]
    assert s["sections"]["speed"] == "missing" and s["sections"]["knee"] == "missing"
    assert [Path(f).name for f in s["figures"]] == ["fig_frf_run1.png"]


def test_unreadable_input_exits_2_naming_the_file(inputs, tmp_path):
    bad = tmp_path / "broken.h5"
    bad.write_bytes(b"not hdf5 at all")
    proc = run_cli("report", "--runs", str(bad), "--out", str(tmp_path / "r"), check=2)
    assert str(bad) in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    # a file of the wrong kind passed as a fit
    proc = run_cli("report", "--fit", str(inputs["shaker"]), "--out", str(tmp_path / "r"), check=2)
    assert str(inputs["shaker"]) in proc.stderr and "modal_fit" in proc.stderr
    # a track without its speed
    t = tmp_path / "t.h5"
    with h5py.File(t, "w") as h:
        h.attrs["kind"] = "track"
    proc = run_cli("report", "--tracks", str(t), "--out", str(tmp_path / "r"), check=2)
    assert "mean_speed_mm_s" in proc.stderr and str(t) in proc.stderr


def test_report_with_the_real_simulator(inputs, tmp_path):
    """Files written by labkit.sim itself (SweepResult.to_h5, SimResult.to_h5), and a knee drive
    with no sim_result, simulated by the report through the executor."""
    from labkit.sim import RobotParams, Shaker, simulate, sweep

    p = RobotParams()
    sw = sweep(p, Shaker(freq_hz=240.0, amp_um=25.0), values=[150.0, 250.0, 300.0], draws=2, duration_s=0.2,
               scheduler="serial", quiet=True)
    sweep_h5 = sw.to_h5(tmp_path / "sweep_real.h5")
    res_h5 = simulate(p, Shaker(freq_hz=200.0, amp_um=25.0), duration_s=0.2, seed=0).to_h5(tmp_path / "r200.h5")
    params = p.to_toml(tmp_path / "robot.toml")
    out = tmp_path / "rep"
    proc = run_cli("report", "--runs", str(inputs["shaker"]), "--tracks", *[str(inputs[f"track{i}"]) for i in range(4)],
                   "--sim", str(sweep_h5), str(res_h5), "--params", str(params), "--knee-duration-s", "0.2",
                   "--knee-drive", "200:25", "300:25", "240:40",
                   "--workers", "1", "--out", str(out), "--json")
    s = last_json(proc)
    assert s["sections"]["speed"] == "ok" and s["sections"]["knee"] == "ok" and s["sections"]["agreement"] == "ok"
    data = json.loads((out / "agreement.json").read_text())
    knee = data["details"]["knee"]
    assert set(knee) >= {"200Hz_25um", "300Hz_25um"}
    assert "No measured knee record at 240 Hz, 40 um" in s["notes"]["knee"]      # drawn, simulated only
    assert len([f for f in s["figures"] if "fig_knee_" in f]) == 3
    assert knee["200Hz_25um"]["provenance"]["simulated"] == str(res_h5)          # from the file
    assert knee["300Hz_25um"]["provenance"]["simulated"].startswith(f"simulate({params}")   # simulated here
    for k in ("200Hz_25um", "300Hz_25um"):
        assert knee[k]["amplitude_sim_mm_s"] > 0 and knee[k]["amplitude_meas_mm_s"] > 0
    speed = data["details"]["speed"][str(sweep_h5)]
    # measured 150..300 Hz points against the sweep's nominal+draw mean, by hand
    mean = np.abs(sw.speeds_mm_s).mean(axis=1)          # magnitudes: measured speed has no sign
    sim_at = np.interp([150.0, 200.0, 250.0, 300.0], sw.values, mean)
    assert speed["rms_error_mm_s"] == pytest.approx(np.sqrt(np.mean((sim_at - SHAKER_SPEED[:4]) ** 2)))
