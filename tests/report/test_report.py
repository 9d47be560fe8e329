"""labkit report end to end on files in the agreed layouts (no simulator needed: --no-simulate)."""
from __future__ import annotations

import json
import re
from pathlib import Path

import h5py
import numpy as np
import pytest
from report_data import SHAKER_SPEED

from clihelpers import last_json, run_cli


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
                                   "patterns": "ok", "tracks": "ok", "agreement": "ok"}
    html = (out / "report.html").read_text()
    # self-contained: no external URL, no script, no stylesheet link, every figure inline as SVG
    assert not re.search(r"(src|href)\s*=\s*\"(https?:|//|file:)", html)
    assert "<script" not in html.lower() and "<link" not in html.lower() and "<img" not in html.lower()
    # frf + stabilisation for 2 fit groups, speed, knee (all drives in one), tracked paths (no video here)
    assert html.count("<svg ") == len(summary["figures"]) == len(summary["svgs"]) == 7
    for fig in summary["figures"]:
        assert Path(fig).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # speed against the sweep: measured 3.0, 4.2, 2.5, 2.9, 0.0 at 150..600 Hz; the Monte Carlo mean
    # 3.5, 5.0, 3.0, 3.5, and 0.5 + (0 - 0.5) * 200/400 = 0.25 at 600 Hz
    err = np.array([0.5, 0.8, 0.5, 0.6, 0.25])
    assert summary["speed_rms_error_mm_s"] == pytest.approx(np.sqrt(np.mean(err ** 2)), rel=1e-9)
    # the nominal robot (draw 0 = 0.9 x base): 3.15, 4.5, 2.7, 3.15, 0.225, judged relative to RMS measured
    meas = np.array([3.0, 4.2, 2.5, 2.9, 0.0])
    err_nominal = np.array([3.15, 4.5, 2.7, 3.15, 0.225]) - meas
    rel = np.sqrt(np.mean(err_nominal ** 2)) / np.sqrt(np.mean(meas ** 2))
    rows = {(r["comparison"], r["metric"]): r for r in summary["agreement"]}
    nominal = rows[("speed, nominal robot vs sweep.h5", "relative RMS error (RMS error / RMS measured)")]
    assert nominal["value"] == pytest.approx(rel) and nominal["verdict"] == "pass"       # 0.08 <= 0.30
    assert summary["speed_rms_error_nominal_mm_s"] == pytest.approx(np.sqrt(np.mean(err_nominal ** 2)))
    # draws are 0.9..1.1 x base: the 10-90 % band is 0.92..1.08 x base and every measured speed lies below
    # every draw: coverage 0 (expected 0.8), median percentile 0 -> the band comparison fails
    band = rows[("speed, Monte Carlo band vs sweep.h5", "fraction of measured speeds inside the 10\u201390 % band")]
    assert band["value"] == 0.0 and band["verdict"] == "fail"
    assert "median percentile of the measured speeds within the draws: 0 " in band["band_statistic"]
    # knee: 200 Hz measured firm (1.05 x tray), simulated firm (1.1 x tray) -> ratio 1.1/1.05, in phase
    ratio = rows[("knee @ 200 Hz, 25 um", "amplitude ratio (sim/meas)")]
    assert ratio["value"] == pytest.approx(1.1 / 1.05, rel=1e-3) and ratio["verdict"] == "pass"
    assert abs(rows[("knee @ 200 Hz, 25 um", "phase difference (sim - meas)")]["value"]) < 1.0
    # patterns: knee records firm/firm and jumping/jumping; the sweep's feet say partial at 200 and
    # 300 Hz, but the observed patterns there are classified from knee records: a different
    # observable, shown and not judged (no sweep row)
    assert rows[("leg pattern (knee records)", "fraction of drives with the same pattern")]["value"] == 1.0
    assert ("leg pattern (sweeps)", "fraction of drives with the same pattern") not in rows
    assert summary["verdicts"]["patterns"] == "pass"
    assert html.count("not compared (different classifiers)") == 2
    assert summary["verdicts"]["frf"] == "pass" and summary["verdicts"]["speed"] == "fail"
    assert summary["verdicts"]["agreement"] == "fail"
    # the sweep is described by its range, not by its base scenario's frequency
    assert "freq_hz 100\u2013800 Hz (7 points), amp_um 25, 5 draws of 1 s" in html
    assert "freq_hz: 240" not in html and "freq_hz 240" not in html
    # provenance once: each input's checksum and the command appear once on the page; the
    # sections refer to the inputs by number; no absolute path anywhere on the page
    data = json.loads((out / "agreement.json").read_text())
    sweep = next(f for f in data["sections"]["speed"]["provenance"]["files"] if f["path"] == str(inputs["sweep"]))
    assert html.count(sweep["sha256"]) == 1
    assert html.count(f'href="#input-{sweep["number"]}"') == sum(
        str(inputs["sweep"]) in [f["path"] for f in sec["provenance"]["files"]]
        for sec in data["sections"].values() if sec["provenance"])
    assert html.count('<div class="provenance">') == 7 and html.count("command (from the folder") == 1
    assert str(tmp_path) not in html and str(inputs["sweep"]) not in html
    assert data["meta"]["command"].startswith("labkit report --runs in/inchip.h5")
    assert data["meta"]["command"].endswith("--out rep")
    assert data["meta"]["tolerances"]["speed_relative_rms_max"] == 0.30
    # headline numbers for --compare
    assert data["headline"]["inchip_mode1_freq_hz"]["value"] == pytest.approx(438.0)
    assert data["headline"]["speed_band_coverage"]["value"] == 0.0


def test_tolerance_option_changes_the_verdict(inputs, tmp_path):
    args = ["--runs", str(inputs["shaker"]), "--sim", str(inputs["sim_200"]), "--no-simulate"]
    s = last_json(run_cli("report", *args, "--out", str(tmp_path / "a"), "--json"))
    assert s["verdicts"]["knee"] == "pass"                   # ratio 1.1 / 1.05 = 1.048 within 1.33
    s = last_json(run_cli("report", *args, "--tolerance", "knee_amplitude_ratio_max=1.02",
                          "--out", str(tmp_path / "b"), "--json"))
    assert s["verdicts"]["knee"] == "fail"
    proc = run_cli("report", *args, "--tolerance", "nope=1", "--out", str(tmp_path / "c"), check=2)
    assert "nope" in proc.stderr and len(proc.stderr.strip().splitlines()) == 1


def test_compare_two_reports(inputs, tmp_path):
    from labkit.analysis.report import build_report

    # the two reports in-process (the CLI path of building one is tested above); the comparison by the CLI
    kw = {"runs": [str(inputs["shaker"])], "sims": [str(inputs["sim_200"])], "simulate_knee": False}
    build_report(tmp_path / "a", **kw)
    build_report(tmp_path / "b", fit=str(inputs["fit"]), **kw)
    c = last_json(run_cli("report", "--compare", str(tmp_path / "a"), str(tmp_path / "b"), "--json"))
    rows = {r["key"]: r for r in c["rows"]}
    assert rows["knee_amplitude_ratio_median"]["a"] == pytest.approx(1.1 / 1.05, rel=1e-3)
    assert rows["knee_amplitude_ratio_median"]["change"] == pytest.approx(0.0, abs=1e-12)
    assert rows["inchip_mode1_freq_hz"]["a"] is None and rows["inchip_mode1_freq_hz"]["b"] == 438.0
    assert rows["inchip_mode1_freq_hz"]["b_text"] == "438 \u00b1 3"
    text = run_cli("report", "--compare", str(tmp_path / "a"), str(tmp_path / "b")).stdout
    assert "inchip mode 1 frequency (Hz)" in text and "438 \u00b1 3" in text
    # section verdicts side by side too: B has a fit (FRF judged), A has not
    verdicts = {v["section"]: v for v in c["verdicts"]}
    assert verdicts["frf"]["a"] == "missing" and verdicts["frf"]["b"] == "pass"
    assert verdicts["knee"]["a"] == verdicts["knee"]["b"] == "pass"
    # ... and as a page of its own
    c = last_json(run_cli("report", "--compare", str(tmp_path / "a"), str(tmp_path / "b"), "--out",
                          str(tmp_path / "cmp"), "--json"))
    page = (tmp_path / "cmp" / "compare.html").read_text()
    assert c["html"] == str(tmp_path / "cmp" / "compare.html")
    assert "inchip mode 1 frequency (Hz)" in page and "438 ± 3" in page and "<script" not in page
    assert page.count('class="badge pass"') >= 3
    run_cli("report", "--compare", str(tmp_path / "a"), str(tmp_path / "b"), "--out", str(tmp_path / "cmp"),
            check=2)                                              # no silent overwrite without --force
    proc = run_cli("report", "--compare", str(tmp_path / "a"), str(tmp_path), check=2)
    assert "agreement.json" in proc.stderr


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
    assert html.count('class="verdict') == 7                 # every section says what it concluded
    # an in-chip run alone: its measured FRFs are drawn, without a model curve
    proc = run_cli("report", "--runs", str(inputs["inchip"]), "--out", str(tmp_path / "rep2"), "--json")
    s = last_json(proc)
    assert s["sections"]["frf"] == "ok" and "no model curve" in s["notes"]["frf"]
    assert s["sections"]["speed"] == "missing" and s["sections"]["knee"] == "missing"
    assert [Path(f).name for f in s["figures"]] == ["fig_frf_run1.png"]
    assert s["verdicts"]["frf"] == "not judged" and s["verdicts"]["speed"] == "missing"


def test_unreadable_input_exits_2_naming_the_file(inputs, tmp_path):
    bad = tmp_path / "broken.h5"
    bad.write_bytes(b"not hdf5 at all")
    proc = run_cli("report", "--runs", str(bad), "--out", str(tmp_path / "r"), check=2)
    assert str(bad) in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    # a file of the wrong kind passed as a fit
    proc = run_cli("report", "--fit", str(inputs["shaker"]), "--out", str(tmp_path / "r"), check=2)
    assert str(inputs["shaker"]) in proc.stderr and "modal_fit" in proc.stderr
    # a track without frames, and one with frames but without its speed
    t = tmp_path / "t.h5"
    with h5py.File(t, "w") as h:
        h.attrs["kind"] = "track"
    proc = run_cli("report", "--tracks", str(t), "--out", str(tmp_path / "r"), check=2)
    assert "t_s" in proc.stderr and str(t) in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    with h5py.File(t, "a") as h:
        for key in ("t_s", "x_mm", "y_mm"):
            h[key] = np.linspace(0.0, 1.0, 5)
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
    drawn = json.loads((out / "figure_data.json").read_text())["fig_knee"]["drives"]
    assert [(d["freq_hz"], d["measured"], d["simulated"]) for d in drawn] == [
        (200.0, True, True), (240.0, False, True), (300.0, True, True)]
    assert knee["200Hz_25um"]["provenance"]["simulated"] == str(res_h5)          # from the file
    assert knee["300Hz_25um"]["provenance"]["simulated"].startswith("simulated here (300 Hz")   # simulated here
    assert str(params) in json.dumps(data["sections"]["knee"]["provenance"])
    for k in ("200Hz_25um", "300Hz_25um"):
        assert knee[k]["amplitude_sim_mm_s"] > 0 and knee[k]["amplitude_meas_mm_s"] > 0
    speed = data["details"]["speed"][str(sweep_h5)]["monte_carlo_mean"]
    # measured 150..300 Hz points against the sweep's nominal+draw mean, by hand
    mean = np.abs(sw.speeds_mm_s).mean(axis=1)          # magnitudes: measured speed has no sign
    sim_at = np.interp([150.0, 200.0, 250.0, 300.0], sw.values, mean)
    assert speed["rms_error_mm_s"] == pytest.approx(np.sqrt(np.mean((sim_at - SHAKER_SPEED[:4]) ** 2)))


def test_failed_report_leaves_the_old_one_whole(inputs, tmp_path, monkeypatch):
    """All files of a report are written to a staging folder and moved in only when all exist: a
    failure mid-report (here: the speed figure) leaves the earlier report byte for byte; a new
    report removes the earlier one's figures that it did not draw."""
    from labkit.analysis.report import build_report
    from labkit.analysis.report import figures as figs

    out = tmp_path / "rep"
    build_report(out, runs=[str(inputs["inchip"])])
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert "fig_frf_run1.svg" in before and "report.html" in before

    def broken(*args, **kwargs):
        raise RuntimeError("disk full")

    with monkeypatch.context() as m:
        m.setattr(figs, "speed_figure", broken)
        with pytest.raises(RuntimeError, match="disk full"):
            build_report(out, runs=[str(inputs["inchip"])], tracks=[str(inputs["track4"])])
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before     # no staging folder left either
    s = build_report(out, tracks=[str(inputs["track4"])])
    names = sorted(p.name for p in out.iterdir())
    assert names == ["agreement.json", "fig_speed.png", "fig_speed.svg", "fig_tracks.png", "fig_tracks.svg",
                     "figure_data.json", "report.html"]
    assert s["figures"] == [str(out / "fig_speed.png"), str(out / "fig_tracks.png")]


@pytest.mark.parametrize("tolerance", ["speed_relative_rms_max=nan", "knee_phase_deg_max=-1",
                                       "pattern_agreement_min=1.5", "knee_amplitude_ratio_max=0.5",
                                       "speed_coverage_min=inf"])
def test_a_tolerance_outside_its_meaning_is_bad_input(inputs, tmp_path, tolerance):
    proc = run_cli("report", "--runs", str(inputs["shaker"]), "--tolerance", tolerance,
                   "--out", str(tmp_path / "r"), check=2)
    assert "Traceback" not in proc.stderr
    assert tolerance.split("=")[0] in proc.stderr and "expected" in proc.stderr
    assert not (tmp_path / "r").exists()
