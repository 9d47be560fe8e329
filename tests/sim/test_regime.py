"""Gait regimes, regime maps and edges (labkit.sim.regime; docs/simulator.md, "Regimes and their edges").

Tested against what the classifier did not make: the rigid robot's lift-off when the tray's peak
acceleration (2 pi f)^2 A exceeds g plus adhesion per supported mass (the closed form of
tests/sim/test_oracles.py), and the paper's regimes (Sec. 5.2: firm contact at small tray motion,
jumping "at higher amplitudes").
"""
from __future__ import annotations

import csv
import json
import math

import h5py
import numpy as np
import pytest

from labkit.errors import InputError
from labkit.jsonutil import to_jsonable
from labkit.sim import PZT, Shaker, simulate
from labkit.sim.presets import load
from labkit.sim.regime import (
    DRIVE_KEY,
    STILL_MOTION_UM,
    EdgeSearch,
    Grid,
    RunFeatures,
    Runs,
    changed,
    classify_regime,
    find_edges,
    regime_map,
)
from tests.conftest import last_json, run_cli
from tests.sim.test_oracles import _stiff, _supported_mass_kg

PAPER = load("paper")


def test_tiny_drive_is_still_small_drive_firm_high_g_jumping():
    """One robot (the paper set), 240 Hz: 0.001 um does nothing measurable, 1 um moves the body on its
    legs with every foot down (the paper's firm contact at 2 V), 60 um (14 g) lifts the feet for more
    than a drive period (Sec. 5.2: "individual legs stay in the air for more than one actuation period")."""
    runs = {a: simulate(PAPER, Shaker(240, a), duration_s=0.3, seed=0) for a in (0.001, 1.0, 60.0)}
    regs = {a: classify_regime(r) for a, r in runs.items()}
    assert regs[0.001].regime == "still" and regs[0.001].body_motion_um < STILL_MOTION_UM
    assert regs[1.0].regime == "firm" and regs[1.0].feet["firm_contact"] == 6
    assert regs[1.0].body_motion_um > STILL_MOTION_UM
    assert regs[60.0].regime == "jumping" and regs[60.0].feet["jumping"] >= 3
    assert max(runs[60.0].max_height_um) > 2 * 60.0      # far above the tray's own motion
    # the classifier reads the summary a file stores (JSON) the same way as the run itself
    for r in runs.values():
        stored = json.loads(json.dumps(to_jsonable(r.summary())))
        again = RunFeatures.from_summary(stored, RunFeatures.of(r).body_motion_um)
        assert again == RunFeatures.of(r) and classify_regime(again) == classify_regime(r)


def test_pzt_tiny_voltage_still():
    r = simulate(PAPER, PZT(1800, 0.01), duration_s=0.05, seed=0)
    assert classify_regime(r).regime == "still"


def test_changed_needs_thirty_percent_or_another_regime():
    base = classify_regime(RunFeatures(2.0, ("jumping",) * 6))
    assert not changed(base, classify_regime(RunFeatures(2.5, ("jumping",) * 6)))
    assert changed(base, classify_regime(RunFeatures(2.7, ("jumping",) * 6)))
    assert changed(base, classify_regime(RunFeatures(2.0, ("partial_contact",) * 4 + ("jumping",) * 2)))
    # at rest, a change of round-off size is no edge
    rest = classify_regime(RunFeatures(1e-6, ("firm_contact",) * 6, body_motion_um=0.0))
    assert rest.regime == "still"
    assert not changed(rest, classify_regime(RunFeatures(0.05, ("firm_contact",) * 6, body_motion_um=0.0)))


def test_seed_line_relative_only_for_a_moving_robot():
    from labkit.sim.regime import EdgeReport

    def reg(v):
        return classify_regime(RunFeatures(v, ("jumping",) * 6))

    moving = EdgeReport(reg(2.0), [], (0.02,), seed_runs=[reg(2.2), reg(1.5)])
    assert moving.seed_line().endswith("spread 25 % of it)") and moving.resolved
    assert not EdgeReport(reg(2.0), [], (0.02,), seed_runs=[reg(2.7)]).resolved
    resting = EdgeReport(reg(3e-5), [], (0.02,), seed_runs=[reg(1e-5)])
    assert resting.seed_line().endswith("spread 2e-05 mm/s)")


def test_map_boundary_is_the_lift_off_line():
    """Stiff legs, no adhesion: the feet leave where (2 pi f)^2 A = g and nowhere else on the grid."""
    p = _stiff(c_ad_n=0.0, c_ad_t_n_s=0.0)
    freqs, amps = [100.0, 141.4], [10.0, 20.0, 30.0]
    m = regime_map(p, Grid("shaker", freqs, amps), Runs(duration_s=0.1, workers=2))
    for i, f in enumerate(freqs):
        for j, a in enumerate(amps):
            lifts = (2 * math.pi * f) ** 2 * a * 1e-6 > p.g_m_s2
            assert (m.regimes[i, j] in ("partial", "jumping")) == lifts, (f, a, m.regimes)
            assert lifts or m.regimes[i, j] == "still"


def _lift_amp_um(p, f):
    return (p.g_m_s2 + p.c_ad_n / _supported_mass_kg(p)) / (2 * math.pi * f) ** 2 * 1e6


def test_edges_find_planted_boundaries():
    """Planted: the tray 3 % below the rigid robot's lift-off (2 pi f)^2 A = g. Up in the drive the edge
    lies past 3 % (no foot can leave before) and by 1.05 x lift-off (where test_oracles sees the hop
    above 0.1 um); the same edge in g, down: past 1 - 1/1.03, by 1 - 1/(1.03 x 1.05). No edge the other
    way (a smaller tray or a stronger g keeps every foot down), none in an adhesion of 0."""
    f = 100.0
    p = _stiff(c_ad_n=0.0, c_ad_t_n_s=0.0)
    rep = find_edges(p, Shaker(f, _lift_amp_um(p, f) / 1.03), Runs(duration_s=0.1, workers=2),
                     EdgeSearch(keys=(DRIVE_KEY, "g_m_s2", "c_ad_n")))
    assert rep.base.regime == "still" and rep.resolved
    assert [r.regime for r in rep.seed_runs] == ["still", "still"]       # seeds 1 and 2: no spread
    by = {(e.key, e.direction): e for e in rep.edges}
    up, g_down = by[(DRIVE_KEY, 1)], by[("g_m_s2", -1)]
    assert 0.03 < up.within <= 1.03 * 1.05 - 1 and up.regime in ("partial", "jumping")
    assert 1 - 1 / 1.03 < g_down.within <= 1 - 1 / (1.03 * 1.05)
    for e in (up, g_down):           # the first bracket holding it (2-5 % or 5-10 %) halved twice
        assert e.clear < e.within and e.within - e.clear <= 0.05 / 4 + 1e-12
    for e in (by[(DRIVE_KEY, -1)], by[("g_m_s2", 1)]):
        assert e.within is None and e.clear == 0.20
    assert by[("c_ad_n", 1)].note == "bound" and by[("c_ad_n", 1)].within is None
    lines = rep.lines()[1:]                    # after the seeds' line
    assert rep.lines()[0].startswith("seeds: 2 others give")
    assert lines[0].startswith("edge: ") and ("up:" in lines[0] or "down:" in lines[0])
    assert lines[-1].startswith("no edge within 20 %") and "adhesion" in lines[-1]


def test_cli_regime_map_csv_and_figure(tmp_path):
    out, fig = tmp_path / "map.csv", tmp_path / "map.svg"
    js = last_json(run_cli("simulate", "regime-map", "shaker", "--params", "paper", "--freq-hz", "240",
                           "--amp-um", "0.001,60", "--duration-s", "0.2", "--workers", "1",
                           "--out", str(out), "--figure", str(fig), "--json"))
    assert js["regimes"] == [["still", "jumping"]] and js["counts"]["jumping"] == 1
    rows = list(csv.DictReader(out.open()))
    assert [r["regime"] for r in rows] == ["still", "jumping"] and float(rows[1]["amp_um"]) == 60
    assert fig.read_text().lstrip().startswith("<?xml") and "<svg" in fig.read_text()[:2000]


def test_cli_regime_map_h5(tmp_path):
    out = tmp_path / "map.h5"
    run_cli("simulate", "regime-map", "pzt", "--params", "paper", "--freq-hz", "1800", "--voltage-v", "0.01",
            "--duration-s", "0.05", "--workers", "1", "--out", str(out), "--quiet")
    with h5py.File(out) as f:
        assert f.attrs["kind"] == "sim_regime_map"
        assert f["regime"][()].astype(str).tolist() == [["still"]]
        assert f["voltage_v"].attrs["units"] == "V" and np.isfinite(f["speed_mm_s"][()]).all()


def test_cli_regime_map_read_back_by_labkit_open_and_info(tmp_path):
    """The map the CLI writes is one kind ``labkit.open`` and ``labkit info`` read: the same regimes,
    speeds and counts as the command printed, with the grid's units."""
    import labkit

    out = tmp_path / "map.h5"
    js = last_json(run_cli("simulate", "regime-map", "shaker", "--params", "paper", "--freq-hz", "240",
                           "--amp-um", "0.001,60", "--duration-s", "0.2", "--workers", "1", "--out", str(out),
                           "--json"))
    m = labkit.open(out)
    assert type(m).__name__ == "SimRegimeMap" and m.kind == "sim_regime_map" and m.drive == "shaker"
    assert m.regimes.tolist() == js["regimes"] == [["still", "jumping"]]
    np.testing.assert_allclose(m.speeds_mm_s, js["speeds_mm_s"], rtol=1e-12)
    assert m.flags.tolist() == js["flags"] and m.counts() == js["counts"]
    assert m.level_name == "amp_um" and m.level.tolist() == [0.001, 60.0] and m.freq_hz.tolist() == [240.0]
    assert m.units == {"freq_hz": "Hz", "amp_um": "um", "regime": "label", "speed_mm_s": "mm/s", "flags": "label"}
    assert m.meta["duration_s"] == 0.2 and m.meta["params"] == "paper"
    assert m.to_xarray()["regime"].sel(freq_hz=240.0, amp_um=60.0).item() == "jumping"
    info = last_json(run_cli("info", str(out), "--json"))
    assert info["content"]["kind"] == "sim_regime_map" and info["content"]["counts"] == js["counts"]

    with h5py.File(out, "r+") as f:                 # a grid whose regimes lost a column: named
        del f["regime"]
        f["regime"] = np.array([[b"still"]])
    with pytest.raises(InputError, match=r"regime.*\(1, 2\)"):
        labkit.open(out)


@pytest.mark.parametrize("args, named", [
    (("shaker", "--amp-um", "5:1:x"), "--amp-um"),
    (("shaker", "--voltage-v", "5"), "--voltage-v"),
    (("pzt", "--freq-hz", "-3"), "--freq-hz"),
    (("shaker", "--amp-um", "1e5"), "--amp-um"),
    (("shaker", "--out", "map.txt"), "--out"),
    (("shaker", "--figure", "map.jpg"), "--figure"),
])
def test_cli_regime_map_bad_input_exit_2(tmp_path, args, named):
    proc = run_cli("simulate", "regime-map", *args, "--duration-s", "0.01", cwd=tmp_path, check=2)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and named in lines[0] and "Traceback" not in proc.stderr
    assert not list(tmp_path.iterdir())


def test_cli_edges_stored_and_reported(tmp_path):
    """``--edges`` on a single run: lines in the summary and in the file (what the report reads)."""
    out = tmp_path / "run.h5"
    js = last_json(run_cli("simulate", "shaker", "--params", "paper", "--freq-hz", "240", "--amp-um", "60",
                           "--duration-s", "0.1", "--edges", "--edge-params", "drive,c_ad_n", "--out", str(out),
                           "--json"))
    assert js["regime"]["regime"] == "jumping"
    e = js["edges"]
    assert e["base"]["regime"] == "jumping" and [x["key"] for x in e["edges"]] == ["drive"] * 2 + ["c_ad_n"] * 2
    assert e["lines"][0].startswith("seeds: 2 others give")
    assert all(line.startswith(("edge: ", "no edge within 20 %", "base run NOT resolved")) for line in e["lines"][1:])
    assert len(e["seed_runs"]) == 2 and e["resolved"] == (not e["lines"][1].startswith("base run NOT"))
    from labkit.files import open_file

    run = open_file(out)
    assert run.attrs["regime"]["regime"] == "jumping" and run.attrs["edges"]["lines"] == e["lines"]

    from labkit.analysis.report.build import build_report

    build_report(tmp_path / "report", sims=[str(out)], simulate_knee=False)
    html = (tmp_path / "report" / "report.html").read_text()
    assert "Gait regime of each simulated run" in html and "jumping" in html
    assert e["lines"][1].split(" (")[0] in html          # the nearest edge, as the run stored it


@pytest.mark.parametrize("args, named", [
    (("--edges", "--edge-params", "drive,nope"), "nope"),
    (("--edge-params", "drive"), "--edge-params"),
])
def test_cli_edges_bad_input_exit_2_before_running(tmp_path, args, named):
    proc = run_cli("simulate", "shaker", "--duration-s", "0.01", "--out", "run.h5", *args, cwd=tmp_path, check=2)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and named in lines[0] and not list(tmp_path.iterdir())
