"""``labkit fit``: run files in, robot parameter file + modal_fit file + figures out."""
from __future__ import annotations

import json
import math

import h5py
import numpy as np
import pytest
from fit_runfiles import TRUE_HZ, TRUE_ZETA, write_inchip, write_shaker

from clihelpers import last_json, run_cli
from labkit.cli import main
from labkit.sim import RobotParams


def _fit(capsys, *args: str) -> tuple[int, dict, str]:
    code = main(["fit", *args, "--json"])
    cap = capsys.readouterr()
    lines = [ln for ln in cap.out.splitlines() if ln.strip()]
    return code, (json.loads(lines[-1]) if lines else {}), cap.err


def test_fit_inchip_and_shaker_into_parameter_file(tmp_path, capsys):
    run = write_inchip(tmp_path / "inchip.h5", np.geomspace(200, 5000, 500), seed=1)
    shk = write_shaker(tmp_path / "shaker.h5", np.linspace(100, 500, 60), fn_hz=240.0, zeta=0.1)
    out = tmp_path / "robot.toml"
    code, s, err = _fit(capsys, str(run), str(shk), "--out", str(out), "--no-figures")
    assert code == 0, err
    listed = s["fitted_modes"]
    inchip = [m for m in listed if m["group"] == "inchip"]
    assert [m["index"] for m in listed] == list(range(1, len(listed) + 1))
    np.testing.assert_allclose([m["freq_hz"] for m in inchip], TRUE_HZ, rtol=2e-3)
    np.testing.assert_allclose([m["damping_ratio"] for m in inchip], TRUE_ZETA, rtol=0.05)
    assert all(m["freq_hz_std"] > 0 and m["damping_ratio_std"] > 0 for m in listed)
    shaker = [m for m in listed if m["group"] == "shaker"]
    assert len(shaker) == 1 and shaker[0]["freq_hz"] == pytest.approx(240.0, rel=3e-3)
    # default rule: only the 438 Hz hip mode lies within 15 % of a simulator mode (438, 1200, 1800)
    assert s["assignment"] == {"1": 1, "2": None, "3": None}
    assert "default" in s["assignment_rule"]
    assert [m["dominant_location"] for m in inchip] == ["hip", "body", "knee"]

    p = RobotParams.from_toml(out)
    base = RobotParams()
    assert p.modal_freq_hz[0] == pytest.approx(inchip[0]["freq_hz"], rel=1e-9)
    assert p.modal_damping_ratio[0] == pytest.approx(inchip[0]["damping_ratio"], rel=1e-9)
    assert p.modal_freq_hz[1:] == pytest.approx(base.modal_freq_hz[1:])
    prov = p.provenance
    assert prov["runs"] == [str(run), str(shk)] and prov["method"] == "lscf"
    m1 = prov["modes"]["1"]
    assert m1["source"] == "fit" and m1["fitted_index"] == 1 and m1["runs"] == [str(run)]
    assert m1["k_per_s2"] == pytest.approx((2 * math.pi * m1["freq_hz"]) ** 2)
    assert m1["k_per_s2_std"] == pytest.approx(2 * m1["k_per_s2"] * m1["freq_hz_std"] / m1["freq_hz"])
    assert m1["b_per_s_std"] > 0
    assert prov["modes"]["2"]["source"] == "base"
    assert set(prov["quality"]) == {"inchip", "shaker"} and prov["quality"]["inchip"] > 0.99

    with h5py.File(tmp_path / "robot.fit.h5") as f:
        assert f.attrs["kind"] == "modal_fit"
        g = f["groups/inchip"]
        assert sorted(g["locations"]) == ["body", "hip", "knee"]
        assert g["locations/knee/frf"].attrs["units"] == "(mm/s)/V"
        meas, model = g["locations/knee/frf"][...], g["locations/knee/model"][...]
        assert np.sqrt(np.mean(np.abs(model - meas) ** 2) / np.mean(np.abs(meas) ** 2)) < 0.02
        np.testing.assert_allclose(g["modes/freq_hz"][...], [m["freq_hz"] for m in inchip])
        assert g["modes/freq_hz_std"].attrs["units"] == "Hz"
        assert g["stabilisation/status"].shape == g["stabilisation/order"].shape
        assert g["modes/amplitude"].shape == (3, 3)
        assert json.loads(f.attrs["assignment_json"]) == {"1": 1, "2": None, "3": None}


def test_explicit_assignment_by_frequency_and_index_with_figures(tmp_path, capsys):
    run = write_inchip(tmp_path / "inchip.h5", np.geomspace(200, 5000, 400), seed=2)
    out = tmp_path / "robot.toml"
    code, s, err = _fit(capsys, str(run), "--out", str(out), "--assign", "1=keep,2=830,3=#3",
                        "--band-hz", "300:4800")
    assert code == 0, err
    assert s["assignment"] == {"1": None, "2": 2, "3": 3}
    p = RobotParams.from_toml(out)
    assert p.modal_freq_hz[0] == pytest.approx(RobotParams().modal_freq_hz[0])    # kept from the base
    assert p.modal_freq_hz[1] == pytest.approx(830.0, rel=1e-3)
    assert p.modal_freq_hz[2] == pytest.approx(3400.0, rel=1e-3)
    assert p.k_per_s2[1] == pytest.approx((2 * math.pi * s["fitted_modes"][1]["freq_hz"]) ** 2)
    assert p.provenance["assignment_rule"] == "--assign 1=keep,2=830,3=#3"
    assert p.provenance["band_hz"] == [300.0, 4800.0]
    for fig in s["figures"]:
        with open(fig, "rb") as fh:
            assert fh.read(8) == b"\x89PNG\r\n\x1a\n"
    assert any(f.endswith("inchip.stabilisation.png") for f in s["figures"])
    # the person can also keep everything
    code, s, _ = _fit(capsys, str(run), "--out", str(out), "--assign", "none", "--force", "--no-figures")
    assert code == 0 and s["assignment"] == {"1": None, "2": None, "3": None}
    assert any("no fitted mode assigned" in w for w in s["warnings"])


def test_nan_lines_and_an_interrupted_run_still_fit(tmp_path, capsys):
    run = write_inchip(tmp_path / "cut.h5", np.geomspace(200, 5000, 300), seed=3, nan_at=10,
                       status="interrupted: SIGINT")
    code, s, err = _fit(capsys, str(run), "--out", str(tmp_path / "r.toml"), "--n-modes", "3",
                        "--no-figures")
    assert code == 0, err
    assert len(s["fitted_modes"]) == 3
    assert any("interrupted" in w for w in s["warnings"])


def test_two_inchip_runs_share_poles_and_name_their_channels(tmp_path, capsys):
    a = write_inchip(tmp_path / "day1.h5", np.geomspace(200, 5000, 150), seed=4)
    b = write_inchip(tmp_path / "day2.h5", np.linspace(300, 4500, 120), seed=5)
    code, s, err = _fit(capsys, str(a), str(b), "--out", str(tmp_path / "r.toml"), "--no-figures")
    assert code == 0, err
    np.testing.assert_allclose([m["freq_hz"] for m in s["fitted_modes"]], TRUE_HZ, rtol=3e-3)
    assert sorted(s["nrmse"]["inchip"]) == sorted(f"{d}:{loc}" for d in ("day1", "day2")
                                                  for loc in ("body", "hip", "knee"))
    assert RobotParams.from_toml(tmp_path / "r.toml").provenance["modes"]["1"]["runs"] == [str(a), str(b)]


@pytest.mark.parametrize("extra, message", [
    (["--min-quality", "1.0"], "no usable FRF lines"),
    (["--assign", "1=999"], "no fitted mode within 10% of 999 Hz"),
    (["--assign", "4=438"], "bad simulator mode"),
    (["--assign", "1=#9"], "no fitted mode #9"),
    (["--assign", "1=#1,2=#1"], "used once"),
    (["--band-hz", "5000:100"], "--band-hz"),
    (["--band-hz", "1000:1010"], "at least 12"),
])
def test_bad_options_exit_2_with_one_line(tmp_path, capsys, extra, message):
    run = write_inchip(tmp_path / "r.h5", np.geomspace(200, 5000, 200))
    code, s, err = _fit(capsys, str(run), "--out", str(tmp_path / "o.toml"), "--no-figures", *extra)
    assert code == 2
    assert message in s["error"], s
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_wrong_files_exit_2_naming_the_file(tmp_path):
    bad = tmp_path / "track.h5"
    with h5py.File(bad, "w") as f:
        f.attrs["kind"] = "track"
    p = run_cli("fit", str(bad), "--out", str(tmp_path / "o.toml"), "--json", check=2)
    assert str(bad) in last_json(p)["error"] and "kind" in last_json(p)["error"]
    p = run_cli("fit", str(tmp_path / "missing.h5"), "--out", str(tmp_path / "o.toml"), check=2)
    assert "missing.h5" in p.stderr and len(p.stderr.strip().splitlines()) == 1
