"""The files users have: UFF 58 (written by pyuff), Touchstone (written by scikit-rf) and CSV with
named columns, read by labkit.analysis.modal.io.read_frf and ``labkit fit``, fitted against the
modes they were made from (with coverage of the stated uncertainty); UFF 55/58 written back;
mode shapes and MAC; ``labkit fit --poles``; bad files and options exit 2 with one line."""
from __future__ import annotations

import numpy as np
import pytest

from clihelpers import last_json, run_cli
from labkit.analysis.modal.fit import fit_modes
from labkit.analysis.modal.io import read_frf
from labkit.analysis.modal.shapes import mac, pair_modes, shape_table
from labkit.analysis.modal.synth import synthetic_frf

pyuff = pytest.importorskip("pyuff")      # both in the test extra: CI runs these
skrf = pytest.importorskip("skrf")

FN = np.array([438.0, 1200.0])
ZETA = np.array([0.03, 0.02])
#: three locations (body, hip, knee): (locations, modes) modal constants
SHAPES = np.array([[1.0, 0.5], [0.3, 1.0], [0.6, -0.7]]) * 1e6
F = np.linspace(100, 3000, 1200)


def _uff58(path, frfs, f=F, kind_code=11):
    sets = [pyuff.prepare_58(func_type=4, rsp_node=k + 1, rsp_dir=3, ref_node=1, ref_dir=3, ord_data_type=6,
                             abscissa_spacing=1, abscissa_spec_data_type=18, ordinate_spec_data_type=kind_code,
                             orddenom_spec_data_type=13, data=np.asarray(h, complex), x=f, num_pts=f.size,
                             id1=f"trial {k}") for k, h in enumerate(frfs)]
    pyuff.UFF(str(path)).write_sets(sets, mode="overwrite")


def _covered(fits) -> tuple[float, float]:
    r = np.array([[[m.freq_hz, m.freq_hz_std, m.damping_ratio, m.damping_ratio_std] for m in ft.modes]
                  for ft in fits])
    assert r.shape[1:] == (2, 4)
    return (float(np.mean(np.abs(r[..., 0] - FN) <= 2 * r[..., 1])),
            float(np.mean(np.abs(r[..., 2] - ZETA) <= 2 * r[..., 3])))


def test_uff58_written_by_pyuff_reads_back_and_fits(tmp_path):
    H = synthetic_frf(F, FN, ZETA, SHAPES, noise=0.005, seed=1)
    path = tmp_path / "three.uff"
    _uff58(path, H)
    rc = read_frf(path)
    assert rc.frf_kind == "mobility" and rc.names == ["1+z_1+z", "2+z_1+z", "3+z_1+z"]
    np.testing.assert_allclose(rc.frf[0], H[0], rtol=1e-9)
    np.testing.assert_allclose(rc.freq_hz[2], F, rtol=2e-6)     # UFF stores the line step with 6 digits
    fit = fit_modes(rc.freq_hz, rc.frf, locations=rc.names, kind=rc.frf_kind)
    got = np.array([m.freq_hz for m in fit.modes])
    np.testing.assert_allclose(got, FN, rtol=1e-3)
    assert [m.dominant_location for m in fit.modes] == ["1+z_1+z", "2+z_1+z"]


def test_uff58_coverage_in_repeated_noisy_trials(tmp_path):
    trials = 30
    H = [synthetic_frf(F, FN, ZETA, SHAPES[:1], noise=0.01, seed=200 + s)[0] for s in range(trials)]
    path = tmp_path / "trials.uff"
    _uff58(path, H)
    rc = read_frf(path)
    assert len(rc.frf) == trials
    cf, cz = _covered([fit_modes(f, h) for f, h in zip(rc.freq_hz, rc.frf)])
    assert cf >= 0.9 and cz >= 0.9, (cf, cz)


def _s1p(path, f_hz, s11):
    net = skrf.Network(frequency=skrf.Frequency.from_f(f_hz, unit="hz"), s=np.asarray(s11)[:, None, None])
    net.write_touchstone(str(path.with_suffix("")))
    return path


def test_touchstone_written_by_scikit_rf_reads_back_and_fits_with_coverage(tmp_path):
    f_hz = F * 1e6                                      # 100 MHz - 3 GHz: the same modes, scaled
    trials = 30
    fits = []
    for s in range(trials):
        h = synthetic_frf(F, FN, ZETA, SHAPES[:1], noise=0.01, seed=300 + s)[0]
        rc = read_frf(_s1p(tmp_path / f"t{s}.s1p", f_hz, 0.4 * h / np.max(np.abs(h))))
        assert rc.names == ["S11"] and rc.frf_kind == "scattering"
        fit = fit_modes(rc.freq_hz, rc.frf, kind=rc.frf_kind)
        for m in fit.modes:                              # back to the synthetic axis for the comparison
            m.freq_hz /= 1e6
            m.freq_hz_std /= 1e6
        fits.append(fit)
    cf, cz = _covered(fits)
    assert cf >= 0.9 and cz >= 0.9, (cf, cz)


def test_csv_with_named_columns_through_labkit_fit(tmp_path):
    H = synthetic_frf(F, FN, ZETA, SHAPES, noise=0.005, seed=4)
    path = tmp_path / "frf.csv"
    cols = np.column_stack([F, np.abs(H[0]), np.degrees(np.angle(H[0])), H[2].real, H[2].imag])
    np.savetxt(path, cols, delimiter=",", header="freq,body_mag,body_deg,knee_re,knee_im", comments="")
    out = tmp_path / "robot.toml"
    s = last_json(run_cli("fit", str(path), "--columns", "f=freq,mag=body_mag,deg=body_deg,re=knee_re,im=knee_im",
                          "--kind", "mobility", "--out", str(out), "--uff", "--no-figures", "--json"))
    got = np.array([m["freq_hz"] for m in s["fitted_modes"]])
    np.testing.assert_allclose(got, FN, rtol=1e-3)
    assert [m["dominant_location"] for m in s["fitted_modes"]] == ["body_mag", "knee_re"]
    # the modes written back as UFF 55 (poles, residues per node) and the fitted FRFs as UFF 58
    back = pyuff.UFF(s["uff_file"])
    types = list(back.get_set_types())
    assert types.count(55) == 2 and types.count(58) == 2
    m58 = [back.read_sets(i) for i, t in enumerate(types) if t == 58]
    np.testing.assert_allclose(m58[0]["x"], F, rtol=2e-6)
    assert np.sqrt(np.mean(np.abs(m58[0]["data"] - H[0]) ** 2)) < 0.02 * np.sqrt(np.mean(np.abs(H[0]) ** 2))
    fit_back = fit_modes(m58[0]["x"], m58[0]["data"])    # the written model refits to the same modes
    np.testing.assert_allclose([m.freq_hz for m in fit_back.modes], got, rtol=1e-5)


def test_poles_by_hand_on_the_command_line(tmp_path):
    H = synthetic_frf(F, FN, ZETA, SHAPES[:1], noise=0.005, seed=5)
    path = tmp_path / "one.uff"
    _uff58(path, H)
    s = last_json(run_cli("fit", str(path), "--poles", "438,1200", "--out", str(tmp_path / "r.toml"),
                          "--no-figures", "--json"))
    assert [m["freq_hz"] for m in s["fitted_modes"]] == [438.0, 1200.0]
    assert [m["freq_hz_std"] for m in s["fitted_modes"]] == [0.0, 0.0]
    np.testing.assert_allclose([m["damping_ratio"] for m in s["fitted_modes"]], ZETA, rtol=0.03)


def test_misfit_above_the_noise_is_a_warning_on_the_command_line(tmp_path):
    H = synthetic_frf(F, FN, ZETA, SHAPES[:1], noise=0.005, seed=6)
    path = tmp_path / "one.uff"
    _uff58(path, H)
    proc = run_cli("fit", str(path), "--n-modes", "1", "--out", str(tmp_path / "r.toml"), "--no-figures")
    assert "WARNING: well above the noise" in proc.stdout
    assert "misfit" in proc.stderr and "times the noise level" in proc.stderr


def test_mode_shapes_mac_and_pairing():
    H = synthetic_frf(F, FN, ZETA, SHAPES, noise=0.005, seed=7)
    a = fit_modes(F, H, locations=["body", "hip", "knee"])
    b = fit_modes(F, synthetic_frf(F, FN, ZETA, SHAPES, noise=0.005, seed=8), locations=["body", "hip", "knee"])
    # residues of a mobility of modal constants A: R = A / 2 (times j w / j w): shapes follow SHAPES' columns
    true = SHAPES.T.astype(complex)
    M = mac(a, true)
    assert M[0, 0] > 0.999 and M[1, 1] > 0.999
    assert a.mac()[0, 1] == pytest.approx(mac(true)[0, 1], abs=0.01)
    assert pair_modes(a, b) == [(0, 0, pytest.approx(1.0, abs=1e-3)), (1, 1, pytest.approx(1.0, abs=1e-3))]
    table = shape_table(a)
    assert table[1]["dominant_location"] == "hip" and table[1]["shape"]["hip"]["magnitude"] == pytest.approx(1.0)
    assert a.summary()["mac"][0][0] == pytest.approx(1.0)


@pytest.mark.parametrize("name, content, extra, message", [
    ("bad.csv", "freq,a,b\n1,2,3\n", ["--columns", "f=freq,re=nope,im=b"], "no column 'nope'"),
    ("bad.csv", "freq,a,b\n1,2,3\n", ["--columns", "f=freq,mag=a"], "--columns"),
    ("bad.uff", "not a universal file\n", [], "bad.uff"),
    ("bad.s1p", "# Hz S RI R 50\nthis is not numbers\n", [], "bad.s1p"),
    ("time.uff", None, [], "no frequency response function"),
])
def test_bad_files_exit_2_with_one_line(tmp_path, name, content, extra, message):
    path = tmp_path / name
    if content is None:                   # a UFF 58 time history (function type 1), not an FRF
        pyuff.UFF(str(path)).write_sets([pyuff.prepare_58(
            func_type=1, rsp_node=1, rsp_dir=3, ref_node=0, ref_dir=0, ord_data_type=4, abscissa_spacing=1,
            abscissa_spec_data_type=17, ordinate_spec_data_type=12, orddenom_spec_data_type=0,
            data=np.sin(np.arange(256.0)), x=np.arange(256.0) * 1e-3, num_pts=256, id1="time")], mode="overwrite")
    else:
        path.write_text(content)
    proc = run_cli("fit", str(path), *extra, "--out", str(tmp_path / "r.toml"), check=2)
    err = proc.stderr.strip().splitlines()
    assert len(err) == 1 and message in err[0] and "Traceback" not in proc.stderr, proc.stderr


def test_two_port_touchstone_with_the_parameter_named_on_the_command_line(tmp_path):
    h = synthetic_frf(F, FN, ZETA, SHAPES[:1], noise=0.005, seed=9)[0]
    s21 = 0.5 * h / np.max(np.abs(h))
    s = np.zeros((F.size, 2, 2), complex)
    s[:, 0, 0] = 0.9 - 0.4 * s21                      # reflection: the modes as dips
    s[:, 1, 0] = s[:, 0, 1] = s21
    s[:, 1, 1] = 0.1
    skrf.Network(frequency=skrf.Frequency.from_f(F, unit="hz"), s=s).write_touchstone(str(tmp_path / "dut"))
    out = tmp_path / "r.toml"
    got = last_json(run_cli("fit", str(tmp_path / "dut.s2p"), "--columns", "S21", "--out", str(out),
                            "--no-figures", "--json"))
    assert [m["dominant_location"] for m in got["fitted_modes"]] == ["S21", "S21"]
    np.testing.assert_allclose([m["freq_hz"] for m in got["fitted_modes"]], FN, rtol=1e-3)
    both = last_json(run_cli("fit", str(tmp_path / "dut.s2p"), "--columns", "S11,S21", "--out", str(out),
                             "--force", "--no-figures", "--json"))
    np.testing.assert_allclose([m["freq_hz"] for m in both["fitted_modes"]], FN, rtol=1e-3)
    run_cli("fit", str(tmp_path / "dut.s2p"), "--columns", "S31", "--out", str(out), "--force", check=2)
