"""``labkit simulate``: exit codes, JSON last line, HDF5 outputs (real CLI in a subprocess)."""
from __future__ import annotations

import h5py
import pytest

from tests.conftest import last_json, run_cli


def test_shaker_json_and_h5(tmp_path):
    out = tmp_path / "run.h5"
    proc = run_cli("simulate", "shaker", "--freq-hz", "240", "--amp-um", "25", "--duration-s", "0.02",
                   "--out", str(out), "--json")
    js = last_json(proc)
    assert isinstance(js["mean_speed_mm_s"], float)
    assert len(js["patterns"]) == 6 and set(js["patterns"]) <= {"firm_contact", "partial_contact", "jumping"}
    assert len(js["contact_fraction"]) == 6
    assert js["freq_hz"] == 240.0 and js["amp_um"] == 25.0 and js["out"] == str(out)
    with h5py.File(out) as f:
        assert f.attrs["kind"] == "sim_result"


def test_sweep_shaker_json_points_and_h5(tmp_path):
    out = tmp_path / "sweep.h5"
    proc = run_cli("simulate", "sweep", "shaker", "--freq-hz", "200:400:3", "--amp-um", "25", "--draws", "2",
                   "--duration-s", "0.02", "--workers", "1", "--out", str(out), "--json")
    js = last_json(proc)
    assert js["quantity"] == "freq_hz" and js["draws"] == 2
    assert [p["freq_hz"] for p in js["points"]] == [200.0, 300.0, 400.0]
    assert all("mean_speed_mm_s" in p and "std_speed_mm_s" in p for p in js["points"])
    with h5py.File(out) as f:
        assert f.attrs["kind"] == "sim_sweep"
        assert f["speeds_mm_s"].shape == (3, 2) and f["values"].attrs["units"] == "Hz"


def test_sweep_pzt_voltage_json():
    js = last_json(run_cli("simulate", "sweep", "pzt", "--voltage-v", "10,20", "--freq-hz", "1800",
                           "--duration-s", "0.01", "--workers", "1", "--json"))
    assert js["quantity"] == "voltage_v" and js["units"] == "V"
    assert [p["voltage_v"] for p in js["points"]] == [10.0, 20.0]
    assert js["scenario"]["freq_hz"] == 1800.0


def test_sweep_pzt_mass_text_output():
    proc = run_cli("simulate", "sweep", "pzt", "--mass-mg", "0.33,1.5", "--freq-hz", "1800", "--voltage-v", "20",
                   "--duration-s", "0.01", "--workers", "1")
    assert "mass_mg" in proc.stdout and "1.5" in proc.stdout


@pytest.mark.parametrize("args, needle", [
    (["sweep", "shaker", "--freq-hz", "150:2000", "--amp-um", "25"], "--freq-hz"),
    (["sweep", "shaker", "--freq-hz", "150:x:4"], "--freq-hz"),
    (["sweep", "pzt", "--mass-mg", "0.3:2:0"], "--mass-mg"),
    (["sweep", "shaker", "--freq-hz", "100:200:3", "--amp-um", "5:10:2"], "--amp-um"),
    (["sweep", "shaker", "--freq-hz", "240"], "range"),
    (["shaker", "--amp-um", "abc"], "--amp-um"),
    (["pzt", "--freq-hz", "-5"], "--freq-hz"),
    (["sweep", "shaker", "--freq-hz", "100:200:3", "--draws", "two"], "--draws"),
    (["shaker", "--params", "/nonexistent/robot.toml"], "/nonexistent/robot.toml"),
    (["sweep", "shaker", "--freq-hz", "100:200:3", "--accel-limit-g", "0"], "--accel-limit-g"),
    (["sweep", "pzt", "--voltage-v", "1:20:3", "--workers", "0"], "--workers"),
    (["shaker", "--start-height-um", "-3"], "--start-height-um"),
    (["pzt", "--start-height-um", "0.001"], "start_height_um"),
    (["shaker", "--dt-s", "-1e-6"], "--dt-s"),
    (["shaker", "--dt-s", "1"], "dt_s"),
    (["sweep", "shaker", "--freq-hz", "100:200:3", "--step-fraction", "2"], "--step-fraction"),
    (["sweep", "shaker", "--freq-hz", "100:200:3", "--step-fraction", "0"], "--step-fraction"),
    # outside what the model or the machine can do (labkit.sim.core.check_run): the bound is named
    (["shaker", "--amp-um", "1e6"], "<= 1000 um"),
    (["shaker", "--freq-hz", "2000", "--amp-um", "400"], "5000 g"),
    (["shaker", "--freq-hz", "1e9"], "x the robot's highest mode"),
    (["pzt", "--voltage-v", "1e6"], "<= 100 V"),
    (["sweep", "shaker", "--freq-hz", "100:1e6:3"], "--freq-hz"),
    (["sweep", "shaker", "--amp-um", "10:2000:3"], "--amp-um"),
])
def test_bad_input_exits_2_with_one_line(args, needle):
    proc = run_cli("simulate", *args, "--duration-s", "0.01", check=2)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, proc.stderr
    assert needle in lines[0]


@pytest.mark.parametrize("kind", ["shaker", "pzt", "sweep"])
def test_a_run_beyond_the_step_budget_is_refused_before_it_starts(kind):
    """--duration-s 1e12 asked for ~6e16 steps (an ArrayMemoryError of 1.67 EiB); now one line
    naming the longest duration, MAX_STEPS steps of the run's default step."""
    from labkit.sim import PZT, RobotParams, Shaker
    from labkit.sim.core import MAX_STEPS, default_dt

    drive = PZT() if kind == "pzt" else Shaker()
    args = ["sweep", "shaker", "--freq-hz", "240,300"] if kind == "sweep" else [kind]
    proc = run_cli("simulate", *args, "--duration-s", "1e12", check=2, timeout=60)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "--duration-s" in lines[0], proc.stderr
    assert f"<= {MAX_STEPS * default_dt(RobotParams(), drive):.4g} s" in lines[0]


def test_start_height_and_dt_check():
    """A drop from 200 um: nothing touches the ground for the first 6 ms (free fall,
    sqrt(2 H / g) = 6.4 ms); --dt-check reports both steps and a verdict."""
    js = last_json(run_cli("simulate", "pzt", "--voltage-v", "0", "--start-height-um", "200", "--duration-s",
                           "0.006", "--dt-check", "--json"))
    assert js["start_height_um"] == 200.0 and sum(js["impacts"]) == 0
    c = js["dt_check"]
    assert c["quarter_dt_s"] == pytest.approx(c["dt_s"] / 4)
    assert len(c["default"]["speeds_mm_s"]) == len(c["quarter"]["speeds_mm_s"]) == 4
    assert c["converged"] is True and c["chaotic"] is False
    text = run_cli("simulate", "shaker", "--duration-s", "0.01", "--dt-check").stdout
    assert "dt check (4 seeds)" in text and "quarter step" in text


def test_dt_s_sets_the_step():
    """--dt-s: the step a run uses (PZT: rounded down so that a half drive period is a whole
    number of steps, here 1 / (2 x 1800 Hz) / 31 for 9e-6 s)."""
    js = last_json(run_cli("simulate", "shaker", "--duration-s", "0.01", "--dt-s", "2e-6", "--json"))
    assert js["dt_s"] == 2e-6 and js["n_steps"] == 5000
    js = last_json(run_cli("simulate", "pzt", "--duration-s", "0.01", "--dt-s", "9e-6", "--json"))
    assert js["dt_s"] == pytest.approx(0.5 / 1800 / 31) and js["dt_s"] <= 9e-6


def test_bad_params_file_names_file_and_key(tmp_path):
    bad = tmp_path / "robot.toml"
    bad.write_text("not_a_parameter = 3\n")
    proc = run_cli("simulate", "shaker", "--params", str(bad), "--duration-s", "0.01", check=2)
    assert str(bad) in proc.stderr and "not_a_parameter" in proc.stderr
    assert proc.stderr.count("\n") == 1


def test_scenario_names_match_the_registry():
    from labkit.commands.simulate import SCENARIO_NAMES
    from labkit.sim.scenarios import SCENARIOS

    assert list(SCENARIO_NAMES) == list(SCENARIOS)


def test_scenario_cli_quick_writes_figure(tmp_path):
    proc = run_cli("simulate", "scenario", "ablations", "--quick", "--out", str(tmp_path), "--json")
    js = last_json(proc)
    assert js["name"] == "ablations"
    assert (tmp_path / "sim_ablations.png").stat().st_size > 1000
    assert set(js["runs"]) == {"full model", "no adhesion", "no squeeze film"}


def test_every_checked_run_says_its_step_even_without_an_error_estimate():
    """The default run (paper set, 240 Hz, 25 um) is chaotic: its starts 0.05 um apart differ at
    every step tried, so it has no step error; its text still has the step line, saying so, and
    the line agrees with --json."""
    out = run_cli("simulate", "shaker").stdout
    js = last_json(run_cli("simulate", "shaker", "--json"))
    step = [ln for ln in out.splitlines() if ln.startswith("  step: ")]
    assert len(step) == 1, out
    conv = js["convergence"]
    assert step[0].startswith(f"  step: {conv['status']} at ")
    if conv["step_error_mm_s"] is None:
        assert "step error not estimated" in step[0] and conv["status"] == "chaotic"
    else:
        assert f"step error {conv['step_error_mm_s']:.3g} mm/s" in step[0]
