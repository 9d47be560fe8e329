"""Sweeps and Monte Carlo draws (labkit.sim.sweep, labkit.sim.uncertainty)."""
from __future__ import annotations

import dataclasses
import json

import h5py
import numpy as np
import pytest

from labkit.errors import InputError
from labkit.files import read_sweep_result
from labkit.sim import PZT, RobotParams, Shaker, simulate, sweep
from labkit.sim.core import default_dt
from labkit.sim.uncertainty import DEFAULT_TABLE, check_table, draw_params

DUR = 0.03  # s: a few shaker periods; enough to exercise contact, cheap enough for CI


@pytest.fixture(scope="module")
def params():
    return RobotParams()


@pytest.fixture(scope="module")
def small_sweep(params):
    return sweep(params, Shaker(freq_hz=240, amp_um=25), "freq_hz", [200.0, 300.0], draws=3,
                 duration_s=DUR, scheduler="serial", seed=7, quiet=True)


def test_draw_params_reproducible_and_only_table_fields(params):
    a = draw_params(params, np.random.default_rng(3))
    b = draw_params(params, np.random.default_rng(3))
    c = draw_params(params, np.random.default_rng(4))
    assert a == b
    assert a != c
    touched = set(DEFAULT_TABLE) | {"mass_mg"}  # the total mass follows body + legs
    for f in dataclasses.fields(params):
        nominal, drawn = getattr(params, f.name), getattr(a, f.name)
        if f.name not in touched:
            assert drawn == nominal, f.name
    changed = [k for k in DEFAULT_TABLE if k != "leg_mass_mg" and getattr(a, k) != getattr(params, k)]
    assert len(changed) == len(DEFAULT_TABLE) - 1, "every uncertain field is perturbed"
    assert a.leg_mass_mg != params.leg_mass_mg
    assert a.mass_mg == pytest.approx(a.body_mass_mg + 6 * a.leg_mass_mg)


def test_draw_params_spread_matches_table(params):
    rng = np.random.default_rng(0)
    key = "c_r"
    sigma = DEFAULT_TABLE[key]
    vals = np.array([getattr(draw_params(params, rng, {key: sigma}), key) for _ in range(400)])
    rel = np.log(vals / getattr(params, key))
    assert abs(rel.std() - sigma) < 0.25 * sigma
    assert vals.min() >= 0.02 and vals.max() <= 0.98


def test_bad_table_names_the_key(params):
    with pytest.raises(InputError, match="no_such_field"):
        check_table(params, {"no_such_field": 0.1})
    with pytest.raises(InputError, match="c_r"):
        check_table(params, {"c_r": -1})


def test_serial_equals_processes(params, small_sweep):
    par = sweep(params, Shaker(freq_hz=240, amp_um=25), "freq_hz", [200.0, 300.0], draws=3,
                duration_s=DUR, workers=2, seed=7, quiet=True)
    np.testing.assert_array_equal(par.speeds_mm_s, small_sweep.speeds_mm_s)
    np.testing.assert_array_equal(par.contact_fraction, small_sweep.contact_fraction)
    np.testing.assert_array_equal(par.patterns, small_sweep.patterns)


def test_draw0_is_the_nominal_robot_and_draws_differ(params, small_sweep):
    r = simulate(params, Shaker(freq_hz=300.0, amp_um=25), duration_s=DUR,
                 seed=small_sweep.meta["task_seeds"][0])
    assert small_sweep.speeds_mm_s[1, 0] == r.mean_speed_mm_s
    assert small_sweep.speeds_mm_s.shape == (2, 3)
    assert len(set(small_sweep.speeds_mm_s[0].tolist())) == 3, "perturbed robots give other speeds"
    np.testing.assert_allclose(small_sweep.mean_speed_mm_s, small_sweep.speeds_mm_s.mean(axis=1))
    np.testing.assert_allclose(small_sweep.std_speed_mm_s, small_sweep.speeds_mm_s.std(axis=1, ddof=1))


def test_same_seed_same_numbers_other_seed_other(params, small_sweep):
    again = sweep(params, Shaker(freq_hz=240, amp_um=25), "freq_hz", [200.0, 300.0], draws=3,
                  duration_s=DUR, scheduler="serial", seed=7, quiet=True)
    other = sweep(params, Shaker(freq_hz=240, amp_um=25), "freq_hz", [200.0, 300.0], draws=3,
                  duration_s=DUR, scheduler="serial", seed=8, quiet=True)
    np.testing.assert_array_equal(again.speeds_mm_s, small_sweep.speeds_mm_s)
    assert not np.array_equal(other.speeds_mm_s[:, 1:], small_sweep.speeds_mm_s[:, 1:])


def test_summary_is_json_with_mean_and_spread(small_sweep):
    s = json.loads(json.dumps(small_sweep.summary()))
    assert s["quantity"] == "freq_hz" and s["units"] == "Hz" and s["draws"] == 3
    assert [p["freq_hz"] for p in s["points"]] == [200.0, 300.0]
    for i, p in enumerate(s["points"]):
        assert p["mean_speed_mm_s"] == pytest.approx(small_sweep.mean_speed_mm_s[i])
        assert p["std_speed_mm_s"] == pytest.approx(small_sweep.std_speed_mm_s[i])
        assert sum(p["contact_fraction"].values()) == pytest.approx(1.0, abs=1e-6)
        assert sum(p["patterns"].values()) == 6 * 3


def test_to_h5_kind_units_and_params(tmp_path, params, small_sweep):
    path = small_sweep.to_h5(tmp_path / "s.h5")
    with h5py.File(path) as f:
        assert f.attrs["kind"] == "sim_sweep"
        units = {}
        f.visititems(lambda n, o: units.__setitem__(n, o.attrs.get("units")) if isinstance(o, h5py.Dataset) else None)
        assert all(units.values()), units
        assert units["values"] == "Hz" and units["speeds_mm_s"] == "mm/s" and units["contact_fraction"] == "1"
        np.testing.assert_array_equal(f["speeds_mm_s"][()], small_sweep.speeds_mm_s)
        toml_text = f.attrs["params_toml"]
    (tmp_path / "robot.toml").write_text(toml_text)
    back_params = RobotParams.from_toml(tmp_path / "robot.toml")
    for f in dataclasses.fields(params):
        if f.name != "provenance":
            assert getattr(back_params, f.name) == getattr(params, f.name), f.name
    back = read_sweep_result(path)          # through labkit.open, the kind's one reader
    np.testing.assert_array_equal(back.patterns, small_sweep.patterns)
    for name in ("values", "speeds_mm_s", "contact_fraction", "impacts", "flags", "convergence", "dt_s"):
        np.testing.assert_array_equal(getattr(back, name), getattr(small_sweep, name), err_msg=name)
    assert back.meta == small_sweep.meta and back.scenario == small_sweep.scenario
    assert back.summary()["points"] == small_sweep.summary()["points"]
    with h5py.File(tmp_path / "other.h5", "w") as f:       # another kind: named, not half-read
        f.attrs["kind"] = "sim_points"
        f["values"] = [1.0]
    with pytest.raises(InputError, match="not a simulated sweep: kind 'sim_points'"):
        read_sweep_result(tmp_path / "other.h5")


def test_mass_sweep_pzt_and_shaker_mass_via_params(params):
    s = sweep(params, PZT(freq_hz=1800, voltage_v=20), "mass_mg", [0.33, 2.0], duration_s=0.01,
              scheduler="serial", quiet=True)
    assert s.speeds_mm_s.shape == (2, 1)
    assert s.scenario["type"] == "pzt"
    sh = sweep(params, Shaker(freq_hz=240, amp_um=25), "mass_mg", [0.33], duration_s=0.01,
               scheduler="serial", quiet=True)
    assert np.isfinite(sh.speeds_mm_s).all()


def test_bad_quantity_and_values(params):
    with pytest.raises(InputError, match="not_a_thing"):
        sweep(params, Shaker(freq_hz=240, amp_um=25), "not_a_thing", [1.0], scheduler="serial", quiet=True)
    with pytest.raises(InputError):
        sweep(params, Shaker(freq_hz=240, amp_um=25), "freq_hz", [], scheduler="serial", quiet=True)


def test_acceleration_limit_cuts_amplitude_as_one_over_f_squared(params):
    from labkit.sim.sweep import limit_acceleration

    g = 9.80665
    s = limit_acceleration(Shaker(freq_hz=1000, amp_um=25), 5.0)
    assert s.amp_um == pytest.approx(5.0 * g / (2 * np.pi * 1000) ** 2 * 1e6)
    assert limit_acceleration(Shaker(freq_hz=100, amp_um=25), 5.0).amp_um == 25  # below the cap
    assert limit_acceleration(PZT(freq_hz=1800, voltage_v=20), 5.0) == PZT(freq_hz=1800, voltage_v=20)
    sw = sweep(params, Shaker(freq_hz=240, amp_um=25), "freq_hz", [100.0, 1000.0], duration_s=0.01,
               scheduler="serial", quiet=True, accel_limit_g=5.0)
    amps = [p["amp_um"] for p in sw.summary()["points"]]
    assert amps == [25.0, pytest.approx(s.amp_um)]


def test_dask_equals_serial(params, small_sweep):
    distributed = pytest.importorskip("distributed")  # an optional extra: labkit[dask]
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        on_dask = sweep(params, Shaker(freq_hz=240, amp_um=25), "freq_hz", [200.0, 300.0], draws=3,
                        duration_s=DUR, scheduler=cluster.scheduler_address, seed=7, quiet=True)
    np.testing.assert_array_equal(on_dask.speeds_mm_s, small_sweep.speeds_mm_s)
    np.testing.assert_array_equal(on_dask.patterns, small_sweep.patterns)


def test_sweep_dt_check_reruns_the_nominal_robot_at_a_quarter_step():
    from labkit.sim import PZT, simulate
    from labkit.sim.core import default_dt

    p = RobotParams(c_ad_n=2e-6, foot_pad_um=100.0)       # the film-held, non-chaotic regime (model.md M7)
    s = sweep(p, PZT(1800, 20.0), "voltage_v", [10.0, 20.0], draws=0, duration_s=0.05, scheduler="serial",
              quiet=True, dt_check=True)
    c = s.meta["dt_check"]
    sc = PZT(1800, 20.0)
    quarter = simulate(p, sc, duration_s=0.05, seed=s.meta["task_seeds"][0], dt_s=default_dt(p, sc) / 4)
    assert c["quarter_speed_mm_s"][1] == quarter.mean_speed_mm_s
    assert c["difference_mm_s"][1] == pytest.approx(s.speeds_mm_s[1, 0] - quarter.mean_speed_mm_s)
    pts = s.summary()["points"]
    assert [pt["dt_converged"] for pt in pts] == c["converged"] and all(c["converged"])


def test_step_fraction_runs_every_point_at_that_step():
    """step_fraction: the nominal run of a point is the run at that fraction of its default
    step (same seed), its dt check at a quarter of that; bad fractions are refused."""
    p, sc = RobotParams(c_ad_n=2e-6), Shaker(240, 100)
    s = sweep(p, sc, "amp_um", [100.0], draws=0, duration_s=0.05, scheduler="serial", quiet=True,
              step_fraction=0.5, dt_check=True)
    dt = default_dt(p, sc)
    seed = s.meta["task_seeds"][0]
    half = simulate(p, sc, duration_s=0.05, seed=seed, dt_s=dt / 2).mean_speed_mm_s
    eighth = simulate(p, sc, duration_s=0.05, seed=seed, dt_s=dt / 8).mean_speed_mm_s
    assert s.speeds_mm_s[0, 0] == half
    assert s.meta["dt_check"]["quarter_speed_mm_s"][0] == eighth
    assert s.meta["step_fraction"] == 0.5 and s.summary()["step_fraction"] == 0.5
    for bad in (0.0, 1.5):
        with pytest.raises(InputError) as e:
            sweep(p, sc, "amp_um", [100.0], duration_s=0.05, scheduler="serial", quiet=True, step_fraction=bad)
        assert e.value.key == "step_fraction"
