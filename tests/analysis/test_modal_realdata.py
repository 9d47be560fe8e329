"""Real measured data: the impact test of a free beam shipped with pyuff (tests/data/pyuff_impact,
MIT), fitted by labkit and compared with an independent fit (sdypy-EMA's LSCF, recorded in the
data's README) and with the free-free beam's law; read as UFF 58 through ``labkit fit``."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from clihelpers import last_json, run_cli
from labkit.analysis.modal.fit import fit_modes
from labkit.errors import InputError

DATA = Path(__file__).resolve().parents[1] / "data" / "pyuff_impact"
#: sdypy-EMA 0.31.0 LSCF (pol_order_high=60), see DATA / "README.md"
SDYPY_EMA_HZ = np.array([51.5175, 142.1764, 278.6626, 460.3949, 687.1659, 958.5319])
#: free-free Euler-Bernoulli beam: f_n proportional to (beta_n L)^2
BETA_L = np.array([4.730041, 7.853205, 10.995608, 14.137165, 17.278760, 20.420352])


def _load() -> tuple[np.ndarray, list[np.ndarray]]:
    f = np.arange(0, 1001.0)
    H = [np.genfromtxt(DATA / f"meas_point_{i}.txt", dtype=complex) for i in (1, 2, 3)]
    assert all(h.size == f.size for h in H)
    return f[1:], [h[1:] for h in H]               # the 0 Hz line carries no FRF


def test_six_modes_agree_with_an_independent_fit_within_the_stated_uncertainty():
    f, H = _load()
    fit = fit_modes(f, H, kind="accelerance", band_hz=(20, 1000), locations=["p1", "p2", "p3"])
    got = np.array([[m.freq_hz, m.freq_hz_std] for m in fit.modes])
    assert got.shape == (6, 2), [m.freq_hz for m in fit.modes]
    assert np.all(got[:, 1] > 0)
    assert np.all(np.abs(got[:, 0] - SDYPY_EMA_HZ) <= 2 * got[:, 1]), (got, SDYPY_EMA_HZ)
    # the law of a free-free beam (Euler-Bernoulli; shear and rotary inertia lower the higher modes a little)
    law = (BETA_L / BETA_L[0]) ** 2
    np.testing.assert_allclose(got[:, 0] / got[0, 0], law, rtol=0.005)
    # the fit is honest about real data: the modes are narrower than the 1 Hz lines, and the model
    # (without leakage) does not reach the noise everywhere; both are said, quality is not "0.97"
    assert any("line spacing" in w for w in fit.warnings)
    worst = max(fit.misfit_to_noise.values())
    if worst > 2:
        assert any("misfit" in w for w in fit.warnings) and fit.quality < 0.5
    # mode shapes over the three points (three points cannot tell six shapes apart: MAC is only shape-checked)
    mac = fit.mac()
    assert mac.shape == (6, 6) and np.allclose(np.diag(mac), 1) and np.allclose(mac, mac.T)


def test_circle_fit_on_the_real_beam_is_an_error_not_its_bounds():
    f, H = _load()
    with pytest.raises(InputError, match="bound"):
        fit_modes(f, H, kind="accelerance", band_hz=(20, 1000), method="circle", n_boot=5)


def test_labkit_fit_reads_the_beam_as_uff58_and_writes_uff55(tmp_path):
    pyuff = pytest.importorskip("pyuff")   # in the test extra: CI has it
    f, H = _load()
    uff = tmp_path / "beam.uff"
    sets = [pyuff.prepare_58(func_type=4, rsp_node=1, rsp_dir=3, ref_node=k + 1, ref_dir=3, ord_data_type=6,
                             abscissa_spacing=1, abscissa_spec_data_type=18, ordinate_spec_data_type=12,
                             orddenom_spec_data_type=13, data=h, x=f, num_pts=f.size, id1=f"point {k + 1}")
            for k, h in enumerate(H)]
    pyuff.UFF(str(uff)).write_sets(sets, mode="overwrite")
    out = tmp_path / "beam.toml"
    s = last_json(run_cli("fit", str(uff), "--band-hz", "20:1000", "--out", str(out), "--uff", "--no-figures",
                          "--json"))
    freqs = np.array([m["freq_hz"] for m in s["fitted_modes"]])
    stds = np.array([m["freq_hz_std"] for m in s["fitted_modes"]])
    assert freqs.size == 6 and np.all(np.abs(freqs - SDYPY_EMA_HZ) <= 2 * stds)
    back = pyuff.UFF(s["uff_file"])
    types = list(back.get_set_types())
    assert types.count(55) == 6 and types.count(58) == 3
    modes = [back.read_sets(i) for i, t in enumerate(types) if t == 55]
    np.testing.assert_allclose(sorted(abs(complex(m["eig"])) / (2 * np.pi) for m in modes), freqs, rtol=1e-5)
