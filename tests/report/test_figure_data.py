"""Each figure shows its inputs: the numbers behind the figures (figure_data.json) checked
against values computed here from the inputs, independently of the report."""
from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from report_data import KNEE_DRIVES_HZ, write_real_fit, write_shaker_knees


def test_fine_grid_fit_curve_resolves_the_anti_resonance(tmp_path):
    from scipy.optimize import minimize_scalar

    from labkit.analysis.report import build_report

    fit_h5, fit = write_real_fit(tmp_path / "robot.fit.h5")
    s = build_report(tmp_path / "rep", fit=str(fit_h5))
    data = json.loads(Path(s["figure_data_json"]).read_text())
    body = data["fig_frf_inchip"]["locations"]["body"]
    assert body["fit_grid_points"] >= 2000
    # the anti-resonance of the fitted model, found here by a bounded minimiser on ModalFit.model
    res = minimize_scalar(lambda x: abs(fit.model([x], "body")[0]), bounds=(500.0, 1400.0), method="bounded",
                          options={"xatol": 1e-4})
    f_true, h_true = float(res.x), float(res.fun)
    near = [m for m in body["fit_minima"] if abs(m[0] - f_true) < 0.05 * f_true]
    assert len(near) == 1, body["fit_minima"]
    assert near[0][1] == pytest.approx(h_true, rel=0.01)
    assert near[0][0] == pytest.approx(f_true, rel=0.01)
    # the stored model at the measured lines misses the dip: what a polyline through them would show
    lines = [m for m in body["lines_model_minima"] if abs(m[0] - f_true) < 0.1 * f_true]
    assert lines and lines[0][1] > 1.05 * h_true
    # hip has no zero between its modes (residues of opposite sign): its dip there is shallow
    hip = [m for m in data["fig_frf_inchip"]["locations"]["hip"]["fit_minima"] if 500 < m[0] < 1400]
    assert all(m[1] > 5 * h_true for m in hip)
    # the mode labels carry the fit's values with their uncertainty
    from labkit.analysis.report.numbers import format_uncertain

    m0 = fit.modes[0]
    assert data["fig_frf_inchip"]["modes"][0] == (f"{format_uncertain(m0.freq_hz, m0.freq_hz_std, 'Hz')}, \u03b6 "
                                                  f"{format_uncertain(m0.damping_ratio, m0.damping_ratio_std)}")


def test_every_knee_drive_is_drawn(tmp_path):
    from labkit.analysis.report import build_report

    run = write_shaker_knees(tmp_path / "knees.h5")
    s = build_report(tmp_path / "rep", runs=[str(run)], simulate_knee=False)
    data = json.loads(Path(s["figure_data_json"]).read_text())
    drawn = [d["freq_hz"] for d in data["fig_knee"]["drives"]]
    assert drawn == list(KNEE_DRIVES_HZ)            # all nine, 230-290 Hz included, in order
    assert all(d["measured"] and not d["simulated"] for d in data["fig_knee"]["drives"])
    svg = Path(data["fig_knee"]["svg"]).read_text()
    for f in KNEE_DRIVES_HZ:                         # one titled panel per drive, as text in the SVG
        assert f"{f:.4g} Hz, tray 25 um" in svg
    assert s["sections"]["knee"] == "ok" and "No simulation at 310 Hz" in s["notes"]["knee"]


def test_figures_are_png_200_dpi_and_svg_with_text(tmp_path):
    from PIL import Image

    from labkit.analysis.report import build_report

    run = write_shaker_knees(tmp_path / "knees.h5", freqs_hz=(200.0,))
    s = build_report(tmp_path / "rep", runs=[str(run)], simulate_knee=False)
    for png, svg in zip(s["figures"], s["svgs"]):
        dpi = Image.open(png).info["dpi"]
        assert dpi[0] == pytest.approx(200, abs=1)
        text = Path(svg).read_text()
        assert text.lstrip().startswith("<?xml") and re.search(r"<text\b", text)   # text kept as text


def test_speed_figure_band_is_the_draws_percentiles(inputs, tmp_path):
    """The speed figure's band is the 10-90 % percentiles of the sweep's draws, its line the nominal
    robot (draw 0), and the plot states the nominal robot's RMS error (report_data.write_sweep:
    draws = base x (0.90, 0.95, 1.00, 1.05, 1.10), so linear-interpolated percentiles are 0.92 and
    1.08 x base)."""
    import numpy as np

    from labkit.analysis.report import build_report

    tracks = [str(inputs[f"track{i}"]) for i in range(5)]
    s = build_report(tmp_path / "rep", runs=[str(inputs["shaker"])], tracks=tracks, sims=[str(inputs["sweep"])],
                     simulate_knee=False)
    data = json.loads(Path(s["figure_data_json"]).read_text())["fig_speed"]
    (sim,) = data["sims"]
    base = np.array([2.0, 3.5, 5.0, 3.0, 3.5, 0.5, 0.0])
    assert sim["freq_hz"] == [100.0, 150.0, 200.0, 250.0, 300.0, 400.0, 800.0] and sim["draws"] == 5
    np.testing.assert_allclose(sim["p10_mm_s"], 0.92 * base, rtol=1e-12)
    np.testing.assert_allclose(sim["p90_mm_s"], 1.08 * base, rtol=1e-12)
    np.testing.assert_allclose(sim["nominal_mm_s"], 0.90 * base, rtol=1e-12)
    assert sim["patterns"][1] == "firm_contact" and sim["patterns"][0] == "partial_contact"
    assert "simulated" in data["pattern_rows"]
    # the tracked speeds at the run's frequencies (its videos) and the one track carrying its own
    assert sorted(data["measured_freq_hz"]) == [150.0, 200.0, 250.0, 300.0, 600.0]
    # the headline number is written in the plot itself, not only in the table
    nominal = next(r for r in s["agreement"] if r["comparison"].startswith("speed, nominal robot"))
    rms = nominal["value_text"].split("RMS error ")[1].split(" mm/s")[0]
    assert f"nominal robot: RMS error {rms} mm/s" in Path(data["svg"]).read_text()


def test_knee_traces_share_the_tray_time_axis(inputs, tmp_path):
    """Measured and simulated knee records start at different times (0.00731 s and 0 s); each is
    drawn on the axis where its own tray velocity is ``A sin(2 pi f t)``, so a knee moving with
    the tray (firm contact: 1.05 and 1.1 x the tray) has phase 0 there in both: they do not look
    out of phase, as they did when each was drawn on its own record's clock."""
    from labkit.analysis.report import build_report

    s = build_report(tmp_path / "rep", runs=[str(inputs["shaker"])],
                     sims=[str(inputs["sim_200"]), str(inputs["sim_300"])], simulate_knee=False)
    drives = {d["freq_hz"]: d for d in json.loads(Path(s["figure_data_json"]).read_text())["fig_knee"]["drives"]}
    assert sorted(drives) == [200.0, 300.0]
    firm = drives[200.0]
    assert firm["measured"] and firm["simulated"]
    assert firm["measured_phase_deg"] == pytest.approx(0.0, abs=1.0)
    assert firm["simulated_phase_deg"] == pytest.approx(0.0, abs=1.0)


def test_stabilisation_diagram_marks_the_chosen_poles_and_names_the_locations(inputs, tmp_path):
    """report_data.write_fit: 15 poles at orders 2..10, chosen poles at the three modes; the legend
    names every location's FRF curve (the issue: no legend said which curve was which)."""
    from report_data import MODES_HZ

    from labkit.analysis.report import build_report

    s = build_report(tmp_path / "rep", fit=str(inputs["fit"]))
    data = json.loads(Path(s["figure_data_json"]).read_text())
    for group in ("inchip", "shaker"):
        st = data[f"fig_stabilisation_{group}"]
        assert st["poles"] == 15 and st["chosen_hz"] == list(MODES_HZ)
        svg = Path(st["svg"]).read_text()
        for text in ("|FRF| body", "|FRF| hip", "|FRF| knee", "chosen pole", "stable frequency and damping"):
            assert text in svg, text
