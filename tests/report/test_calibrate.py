"""labkit calibrate: recover a deliberately changed parameter from simulated "measurements"."""
from __future__ import annotations

import numpy as np
import pytest

from labkit.calibrate import Observations, calibrate, parse_names, set_values, speed_task
from labkit.errors import InputError
from tests.conftest import last_json, run_cli

TRUE_MP = 0.6             # modal_participation; the default robot has 0.5
FREQ_HZ = np.array([150.0, 300.0])
AMP_UM = 50.0
DURATION_S = 0.5


def _measured(params):
    return np.array([speed_task((params, f, AMP_UM, DURATION_S, 0))["speed_mm_s"] for f in FREQ_HZ])


def test_recovers_a_changed_parameter():
    from labkit.sim import RobotParams

    p0 = RobotParams()
    meas = _measured(p0.replace(modal_participation=TRUE_MP))
    start = _measured(p0)
    # the change must be visible in the data, or the test would prove nothing
    assert np.max(np.abs(meas - start)) > 0.02, (meas, start)
    obs = Observations(FREQ_HZ, np.full(FREQ_HZ.size, AMP_UM), meas, np.full(FREQ_HZ.size, 0.01))
    cal = calibrate(p0, ["modal_participation"], obs, duration_s=DURATION_S, scan=6, min_std_mm_s=0.001,
                    bounds={"modal_participation": (0.3, 0.8)}, scheduler="serial", quiet=True)
    fitted, std = cal.fitted[0], cal.std[0]
    assert abs(fitted - TRUE_MP) <= max(3 * std, 0.01), (fitted, std)
    assert 0 < std < 0.2 * TRUE_MP                     # an uncertainty that says something
    assert cal.after["rms_error_mm_s"] < 0.5 * cal.before["rms_error_mm_s"]
    assert cal.params.modal_participation == pytest.approx(fitted)
    assert cal.n_sims > 0 and cal.summary()["parameters"]["modal_participation"]["initial"] == 0.5


def test_parameter_names_and_per_mode_elements():
    from labkit.sim import RobotParams

    p = RobotParams()
    names = parse_names(p, ["c_r", "k_per_s2[1]"])
    assert names == [("c_r", None), ("k_per_s2", 1)]
    q = set_values(p, names, [0.3, 6e7])
    assert q.c_r == 0.3 and q.k_per_s2 == (p.k_per_s2[0], 6e7, p.k_per_s2[2])
    for bad in (["nope"], ["k_per_s2"], ["c_r[1]"], ["c_r", "c_r"]):
        with pytest.raises(InputError):
            parse_names(p, bad)


def test_cli_writes_parameter_file_with_provenance(tmp_path):
    from labkit.sim import RobotParams

    meas = _measured(RobotParams().replace(modal_participation=TRUE_MP))
    table = tmp_path / "speeds.csv"
    table.write_text("# measured (here: simulated with modal_participation=0.6)\n"
                     "freq_hz,speed_mm_s,speed_std_mm_s,pattern\n"
                     + "".join(f"{f},{s},0.01,firm_contact\n" for f, s in zip(FREQ_HZ, meas)))
    out = tmp_path / "robot.cal.toml"
    proc = run_cli("calibrate", str(table), "--fit", "modal_participation", "--amp-um", str(AMP_UM),
                   "--duration-s", str(DURATION_S), "--bound", "modal_participation=0.3:0.8", "--workers", "1",
                   "--min-std-mm-s", "0.001", "--max-iterations", "4", "--out", str(out), "--json")
    s = last_json(proc)
    assert s["out"] == str(out) and s["after"]["rms_error_mm_s"] <= s["before"]["rms_error_mm_s"]
    assert "pattern_agreement" in s["after"]            # the pattern column was used
    p = RobotParams.from_toml(out)
    cal = p.provenance["calibration"]
    assert p.modal_participation == pytest.approx(s["parameters"]["modal_participation"]["fitted"])
    assert cal["measured"] == [str(table)] * 2 and "least_squares" in cal["method"]
    assert cal["std"]["modal_participation"] == pytest.approx(s["parameters"]["modal_participation"]["std"])


def test_cli_bad_inputs_exit_2(tmp_path):
    table = tmp_path / "speeds.csv"
    table.write_text("freq_hz,speed_mm_s,speed_std_mm_s\n200,1.0,0.1\n")
    proc = run_cli("calibrate", str(table), "--fit", "no_such_param", "--amp-um", "25",
                   "--out", str(tmp_path / "o.toml"), check=2)
    assert "no_such_param" in proc.stderr
    proc = run_cli("calibrate", str(table), "--fit", "c_r", "--out", str(tmp_path / "o.toml"), check=2)
    assert "--amp-um" in proc.stderr and str(table) in proc.stderr
    bad = tmp_path / "bad.csv"
    bad.write_text("freq_hz,speed\n200,1\n")
    proc = run_cli("calibrate", str(bad), "--fit", "c_r", "--amp-um", "25", "--out", str(tmp_path / "o.toml"),
                   check=2)
    assert "speed_mm_s" in proc.stderr and str(bad) in proc.stderr
