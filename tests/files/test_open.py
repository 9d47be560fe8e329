"""labkit.open reads every file labkit writes; xarray/h5netcdf sees the coordinates; older layouts stay readable.

The expected values come from the files themselves read with plain h5py (an independent
reader), not from labkit's readers.
"""
from __future__ import annotations

import json
import shutil
import warnings
from pathlib import Path

import h5py
import numpy as np
import pytest

import labkit
from clihelpers import REPO, last_json, run_cli
from labkit.errors import InputError
from labkit.h5io import SCHEMA_VERSION

xr = pytest.importorskip("xarray", reason="xarray is in the test extra: pip install -e '.[test]'")
pytest.importorskip("h5netcdf", reason="h5netcdf is in the test extra: pip install -e '.[test]'")

SAMPLE = REPO / "sample_data"
SCHEMA1 = Path(__file__).parent / "schema1"

# every file `labkit sample-data` leaves in sample_data/ (README.md is prose, not data) -> expected class
SAMPLE_KINDS = {
    "inchip.toml": ("ExperimentConfig", "config_inchip"),
    "shaker.toml": ("ExperimentConfig", "config_shaker"),
    "inchip_run.h5": ("InchipRun", "run_inchip"),
    "shaker_run.h5": ("ShakerRun", "run_shaker"),
    "robot.fit.h5": ("ModalFit", "modal_fit"),
    "robot.toml": ("RobotParameters", "robot_params"),
    "shaker_240hz.mkv": ("Video", "video"),
    "shaker_240hz_track.h5": ("Track", "track"),
    "shaker_240hz_track.csv": ("Track", "track_csv"),
}

# per HDF5 sample: group -> the coordinate xarray must find there (and the dataset it indexes)
COORDS = {
    "inchip_run.h5": {"locations/body": ("freq_hz", "frf"), "locations/hip": ("freq_hz", "frf"),
                      "locations/knee": ("freq_hz", "frf"), "points": ("index", "status"),
                      "events": ("time_unix_s", "text")},
    "shaker_run.h5": {"points": ("index", "transmissibility"), "records/p00000": ("t_s", "robot_velocity_mm_s")},
    "shaker_240hz_track.h5": {"/": ("t_s", "x_mm"), "smoothed": ("t_s", "x_mm")},
    "robot.fit.h5": {"groups/inchip/locations/body": ("freq_hz", "frf"),
                     "groups/inchip/locations/knee": ("freq_hz", "model")},
}


def test_every_sample_file_is_listed_here():
    present = {p.name for p in SAMPLE.iterdir() if p.is_file() and p.name != "README.md"}
    assert present == set(SAMPLE_KINDS)


@pytest.mark.parametrize("name", sorted(SAMPLE_KINDS))
def test_every_sample_file_opens_with_labkit_open(name):
    cls, kind = SAMPLE_KINDS[name]
    obj = labkit.open(SAMPLE / name)
    assert type(obj).__name__ == cls and obj.kind == kind
    summary = obj.summary()
    json.dumps(summary, allow_nan=True)             # JSON-able, as `labkit info --json` prints it
    assert summary["kind"] == kind and summary["file"] == str(SAMPLE / name)
    ds = obj.to_xarray()
    assert isinstance(ds, xr.Dataset)
    assert ds.attrs["kind"] == kind


def _h5_groups(path: Path) -> list[str]:
    names = ["/"]
    with h5py.File(path, "r") as f:
        f.visititems(lambda n, o: names.append(n) if isinstance(o, h5py.Group) else None)
    return names


@pytest.mark.parametrize("name", sorted(COORDS))
def test_xarray_h5netcdf_sees_the_coordinates_of_every_sample_file(name):
    path = SAMPLE / name
    for group, (coord, var) in COORDS[name].items():
        with xr.open_dataset(path, engine="h5netcdf", group=group) as ds, h5py.File(path, "r") as f:
            g = f[group]
            assert coord in ds.coords, (name, group, list(ds.coords))
            assert ds[var].dims == (coord,), (name, group, var, ds[var].dims)
            np.testing.assert_array_equal(ds[coord].values, g[coord][()])
            assert ds[coord].attrs["units"] == g[coord].attrs["units"]
    # and no group of a sample file fails to open or names any axis anonymously (an unlabelled
    # dimension is a phony_dim, and xarray warns about the phony_dims default: an error here)
    for group in _h5_groups(path):
        with warnings.catch_warnings():
            warnings.filterwarnings("error", message=".*phony_dims")
            with xr.open_dataset(path, engine="h5netcdf", group=group) as ds:
                for k, v in ds.variables.items():
                    assert not [d for d in v.dims if str(d).startswith("phony_dim")], (name, group, k, v.dims)


def test_fit_file_names_modes_locations_and_covariance_axes():
    path = SAMPLE / "robot.fit.h5"
    with h5py.File(path, "r") as f:
        locations = json.loads(f["groups/inchip"].attrs["locations_json"])
        n_modes = f["groups/inchip/modes/freq_hz"].shape[0]
        n_par = f["groups/inchip/covariance"].shape[0]
    with xr.open_dataset(path, engine="h5netcdf", group="groups/inchip/modes") as ds:
        assert ds["amplitude"].dims == ds["peak"].dims == ("freq_hz", "location")
        assert list(ds["location"].values) == locations and ds.sizes["freq_hz"] == n_modes
        assert ds["damping_ratio"].dims == ("freq_hz",)
    with xr.open_dataset(path, engine="h5netcdf", group="groups/inchip") as ds:
        assert ds["covariance"].dims == ("parameter_i", "parameter_j")
        np.testing.assert_array_equal(ds["parameter_i"].values, np.arange(n_par))
    with xr.open_dataset(path, engine="h5netcdf", group="groups/inchip/stabilisation") as ds:
        assert "chosen_hz" in ds.coords and ds["order"].dims == ("freq_hz",)
    # the label scale is an axis, not a mode column: labkit.open reads the modes it always did
    assert "location" not in labkit.open(path).groups["inchip"].modes


def test_a_track_says_its_scale_and_lost_frames_from_the_h5_and_from_the_csv(tmp_path):
    """The one track reader: the .h5's lost_frames and mm_per_px attributes, read by h5py here;
    a CSV without them counts the rows with no position (a lost frame's cells are empty)."""
    h5 = REPO / "sample_data" / "shaker_240hz_track.h5"
    track = labkit.open(h5)
    with h5py.File(h5) as f:
        assert track.lost_frames == int(f.attrs["lost_frames"]) and track.mm_per_px == float(f.attrs["mm_per_px"])
    p = tmp_path / "t.csv"
    p.write_text("# labkit track of v.mkv; mm_per_px=0.05; quality: 0 ok, 1 degraded, 2 lost\n"
                 "t_s,x_mm,y_mm,quality\n0,1,2,0\n0.1,,,2\n0.2,1,3.87,0\n0.3,,,2\n")
    csv = labkit.open(p)
    assert (csv.kind, csv.lost_frames, csv.mm_per_px) == ("track_csv", 2, 0.05)


def test_frequency_and_time_are_coordinates_in_xarray():
    """The two the issue names: freq_hz of an FRF, t_s of a record and of a track."""
    with xr.open_dataset(SAMPLE / "inchip_run.h5", engine="h5netcdf", group="locations/knee") as ds:
        assert "freq_hz" in ds.coords and ds["frf"].dims == ("freq_hz",)
        assert ds["freq_hz"].attrs["units"] == "Hz"
        peak = float(ds["freq_hz"][np.argmax(np.abs(ds["frf"].values))])
    run = labkit.open(SAMPLE / "inchip_run.h5")
    knee = run.locations["knee"]
    assert peak == float(knee.freq_hz[np.argmax(np.abs(knee.frf))])
    with xr.open_dataset(SAMPLE / "shaker_run.h5", engine="h5netcdf", group="records/p00000") as ds:
        dt = float(h5py.File(SAMPLE / "shaker_run.h5")["records/p00000"].attrs["dt_s"])
        np.testing.assert_allclose(np.diff(ds["t_s"].values), dt, rtol=1e-9)
        assert ds["t_s"].attrs["units"] == "s"
    with xr.open_dataset(SAMPLE / "shaker_240hz_track.h5", engine="h5netcdf") as ds:
        assert "t_s" in ds.coords and ds["x_mm"].dims == ("t_s",)


def test_inchip_run_object_matches_the_file_read_with_h5py():
    run = labkit.open(SAMPLE / "inchip_run.h5")
    with h5py.File(SAMPLE / "inchip_run.h5", "r") as f:
        n = f["points/index"].shape[0]
        assert run.complete_points == n == int(f.attrs["points_planned"])
        assert run.config_toml == f.attrs["config_toml"]
        for loc in ("body", "hip", "knee"):
            np.testing.assert_array_equal(run.locations[loc].frf, f[f"locations/{loc}/frf"][()])
            assert run.units["frf"] == f[f"locations/{loc}/frf"].attrs["units"] == "(mm/s)/V"
        assert set(run.instruments) == set(f["instruments"])
    ds = run.to_xarray()
    assert ds["frf"].dims == ("location", "freq_hz")
    assert list(ds["location"].values) == ["body", "hip", "knee"]


def test_a_run_cut_short_keeps_only_complete_points(tmp_path):
    """The index column is written last: a longer sibling (the point in progress) is not read."""
    path = tmp_path / "cut.h5"
    shutil.copy(SAMPLE / "inchip_run.h5", path)
    with h5py.File(path, "r+") as f:
        n = f["points/index"].shape[0]
        keep = n - 5
        f["points/index"].resize((keep,))              # as if the crash came before index was appended
        last_done = set(f["points/index"][()].tolist())
        cut_rows = {(loc, int(i)) for loc in f["locations"] for i in f[f"locations/{loc}/point_index"][()]
                    if int(i) not in last_done}
    run = labkit.open(path)
    assert run.complete_points == keep
    assert all(col.shape[0] == keep for col in run.points.values())
    kept = sum(run.locations[loc].freq_hz.size for loc in run.locations)
    assert kept == sum(np.isin(labkit.open(SAMPLE / "inchip_run.h5").locations[loc].columns["point_index"],
                               sorted(last_done)).sum() for loc in run.locations)
    assert cut_rows and not cut_rows & {(loc, int(i)) for loc, v in run.locations.items()
                                        for i in v.columns["point_index"]}


# --------------------------------------------------------------------------- older layouts

SCHEMA1_KINDS = {"inchip_run.h5": "run_inchip", "shaker_run.h5": "run_shaker", "robot.fit.h5": "modal_fit",
                 "shaker_240hz_track.h5": "track", "sim_result.h5": "sim_result", "sim_sweep.h5": "sim_sweep",
                 "sim_sweep_set.h5": "sim_sweep_set", "sim_ablations.h5": "sim_ablations"}


def test_schema1_fixtures_are_what_they_claim():
    """Written by labkit before dimension scales (commits up to aac5998): version 1, no scales."""
    assert {p.name for p in SCHEMA1.glob("*.h5")} == set(SCHEMA1_KINDS)
    for name, kind in SCHEMA1_KINDS.items():
        with h5py.File(SCHEMA1 / name, "r") as f:
            assert f.attrs["kind"] == kind and int(f.attrs["schema_version"]) == 1
            assert not _scales(f), name


def _scales(f: h5py.File) -> list[str]:
    found: list[str] = []
    f.visititems(lambda n, o: found.append(n) if isinstance(o, h5py.Dataset) and o.is_scale else None)
    return found


@pytest.mark.parametrize("name", sorted(SCHEMA1_KINDS))
def test_schema1_files_read_like_current_ones(name):
    obj = labkit.open(SCHEMA1 / name)
    assert obj.kind == SCHEMA1_KINDS[name] and obj.schema_version == 1
    json.dumps(obj.summary(), allow_nan=True)
    ds = obj.to_xarray()
    with h5py.File(SCHEMA1 / name, "r") as f:
        if name == "inchip_run.h5":
            assert obj.complete_points == f["points/index"].shape[0]
            for loc in ("body", "hip", "knee"):
                np.testing.assert_array_equal(obj.locations[loc].frf, f[f"locations/{loc}/frf"][()])
            assert "freq_hz" in ds.coords
        elif name == "shaker_run.h5":
            np.testing.assert_array_equal(obj.points["transmissibility"], f["points/transmissibility"][()])
            rec = obj.records()[int(f["points/index"][0])]
            np.testing.assert_allclose(np.diff(rec.t_s), f["records/p00000"].attrs["dt_s"])
        elif name == "robot.fit.h5":
            g = next(iter(f["groups"]))
            np.testing.assert_array_equal(obj.groups[g].modes["freq_hz"], f[f"groups/{g}/modes/freq_hz"][()])
        elif name == "shaker_240hz_track.h5":
            np.testing.assert_array_equal(ds["x_mm"].values, f["x_mm"][()])
            assert obj.mean_speed_mm_s == f.attrs["mean_speed_mm_s"]
        elif name == "sim_result.h5":
            np.testing.assert_array_equal(ds["body_z_um"].values, f["body_z_um"][()])
            np.testing.assert_array_equal(ds["t_s"].values, f["t_s"][()])
        elif name == "sim_sweep_set.h5":
            assert sorted(obj.sweeps) == ["amp_25_um/5_uN", "capped/5_uN"]
            np.testing.assert_array_equal(ds["speeds_mm_s"].values, f["amp_25_um/5_uN/speeds_mm_s"][()])
        elif name == "sim_ablations.h5":
            assert list(obj.runs) == ["full", "no_adhesion"]
            np.testing.assert_array_equal(ds["foot_z_um"].values, f["runs/full/foot_z_um"][()])
        else:
            np.testing.assert_array_equal(ds["freq_hz"].values, f["values"][()])
            np.testing.assert_array_equal(ds["speeds_mm_s"].values, f["speeds_mm_s"][()])


def test_a_schema1_file_can_be_labelled_in_place_for_xarray(tmp_path):
    from labkit.h5io import label_dimensions

    path = tmp_path / "old.h5"
    shutil.copy(SCHEMA1 / "inchip_run.h5", path)
    with h5py.File(path, "r+") as f:
        label_dimensions(f)
    with xr.open_dataset(path, engine="h5netcdf", group="locations/knee") as ds:
        assert "freq_hz" in ds.coords and ds["frf"].dims == ("freq_hz",)
    assert labkit.open(path).complete_points == labkit.open(SCHEMA1 / "inchip_run.h5").complete_points


def test_an_older_fit_file_can_be_labelled_in_place_and_reads_the_same(tmp_path):
    from labkit.analysis.modal.io import label_fit_dimensions

    path = tmp_path / "old.fit.h5"
    shutil.copy(SCHEMA1 / "robot.fit.h5", path)
    with h5py.File(path, "r+") as f:
        label_fit_dimensions(f)
        label_fit_dimensions(f)                 # idempotent
    for group in _h5_groups(path):
        with warnings.catch_warnings():
            warnings.filterwarnings("error", message=".*phony_dims")
            with xr.open_dataset(path, engine="h5netcdf", group=group) as ds:
                for k, v in ds.variables.items():
                    assert not [d for d in v.dims if str(d).startswith("phony_dim")], (group, k, v.dims)
    old, new = labkit.open(SCHEMA1 / "robot.fit.h5"), labkit.open(path)
    for g, fg in old.groups.items():
        assert sorted(new.groups[g].modes) == sorted(fg.modes)
        for k, v in fg.modes.items():
            np.testing.assert_array_equal(new.groups[g].modes[k], v)
    xr.testing.assert_identical(new.to_xarray().drop_attrs(), old.to_xarray().drop_attrs())


def test_a_file_from_a_newer_labkit_is_refused_with_exit_2(tmp_path):
    path = tmp_path / "future.h5"
    shutil.copy(SAMPLE / "shaker_240hz_track.h5", path)
    with h5py.File(path, "r+") as f:
        f.attrs["schema_version"] = 99
    with pytest.raises(InputError, match="schema_version"):
        labkit.open(path)
    proc = run_cli("info", str(path), check=2)
    assert "future.h5" in proc.stderr and "schema_version" in proc.stderr and "Traceback" not in proc.stderr


def test_not_a_labkit_file_is_a_clear_error(tmp_path):
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"not hdf5 at all")
    with pytest.raises(InputError, match="junk.h5"):
        labkit.open(junk)
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f.attrs["kind"] = "spreadsheet"
    with pytest.raises(InputError, match="kind"):
        labkit.open(other)
    with pytest.raises(InputError, match="no such file"):
        labkit.open(tmp_path / "missing.h5")


# --------------------------------------------------------------------------- simulations (not in sample_data)

@pytest.fixture(scope="module")
def sim_files(tmp_path_factory):
    from labkit.sim import RobotParams, Shaker, simulate, sweep

    d = tmp_path_factory.mktemp("sim")
    r = simulate(RobotParams(), Shaker(freq_hz=240.0, amp_um=2.0), duration_s=0.02, seed=0)
    r.to_h5(d / "run.h5")
    s = sweep(RobotParams(), Shaker(freq_hz=240.0, amp_um=2.0), quantity="freq_hz", values=[200.0, 300.0],
              draws=2, duration_s=0.02, seed=0, quiet=True, workers=1)
    s.to_h5(d / "sweep.h5")
    return r, s, d


def test_simulation_result_opens_with_time_as_coordinate(sim_files):
    r, _, d = sim_files
    obj = labkit.open(d / "run.h5")
    assert obj.kind == "sim_result" and obj.schema_version == SCHEMA_VERSION
    np.testing.assert_array_equal(obj.t_s, r.t_s)
    assert obj.mean_speed_mm_s == pytest.approx(r.mean_speed_mm_s)
    with xr.open_dataset(d / "run.h5", engine="h5netcdf") as ds:
        assert "t_s" in ds.coords and ds["body_z_um"].dims == ("t_s",)
        np.testing.assert_array_equal(ds["body_z_um"].values, r.body_z_um)
        assert ds["foot_z_um"].dims == ("t_s", "leg") and ds["impacts"].dims == ("leg",)
        assert not [d for d in ds.dims if str(d).startswith("phony_dim")]
    assert obj.to_xarray()["foot_z_um"].dims == ("t_s", "leg")
    assert obj.params == r.params


def test_simulated_sweep_opens_with_its_quantity_as_coordinate(sim_files):
    _, s, d = sim_files
    obj = labkit.open(d / "sweep.h5")
    assert obj.kind == "sim_sweep" and obj.quantity == "freq_hz"
    with xr.open_dataset(d / "sweep.h5", engine="h5netcdf") as ds:
        assert "freq_hz" in ds.coords and ds["mean_speed_mm_s"].dims == ("freq_hz",)
        np.testing.assert_array_equal(ds["freq_hz"].values, [200.0, 300.0])
        np.testing.assert_allclose(ds["mean_speed_mm_s"].values, s.mean_speed_mm_s)
        # 2 points x 2 draws: only the labels (axes attribute -> dimension scales) tell them apart
        assert ds["speeds_mm_s"].dims == ("freq_hz", "draw")
        np.testing.assert_array_equal(ds["speeds_mm_s"].values, s.speeds_mm_s)
        assert ds["contact_fraction"].dims == ("freq_hz", "draw", "foot", "mode")
        assert not [d for d in ds.dims if str(d).startswith("phony_dim")]
    assert obj.to_xarray()["speeds_mm_s"].dims == ("freq_hz", "draw")


def test_labkit_info_covers_every_sample_file():
    for name, (_, kind) in SAMPLE_KINDS.items():
        info = last_json(run_cli("info", str(SAMPLE / name), "--json"))
        content = info.get("content", {})
        assert content.get("kind") == kind or info.get("kind") == kind, (name, info)


def test_scenario_files_open(sim_files, tmp_path):
    """The multi-run and multi-sweep files of `labkit simulate scenario`, written by their own writers."""
    from labkit.sim.scenarios.io import write_runs, write_sweep_set
    from labkit.sim.scenarios.runs import PointSet

    r, s, _ = sim_files
    write_runs(tmp_path / "abl.h5", "sim_ablations", [("full", r), ("no adhesion", r)], {"note": "test"})
    runs = labkit.open(tmp_path / "abl.h5")
    assert runs.kind == "sim_ablations" and list(runs.runs) == ["full", "no_adhesion"]
    np.testing.assert_array_equal(runs.runs["full"]["t_s"], r.t_s)
    assert runs.to_xarray("no_adhesion")["foot_z_um"].dims == ("t_s", "leg")

    write_sweep_set(tmp_path / "set.h5", {"amp_25_um/5_uN": s, "capped/5_uN": s})
    sset = labkit.open(tmp_path / "set.h5")
    assert sset.kind == "sim_sweep_set" and sorted(sset.sweeps) == ["amp_25_um/5_uN", "capped/5_uN"]
    np.testing.assert_array_equal(sset.to_xarray("capped/5_uN")["speeds_mm_s"].values, s.speeds_mm_s)

    import dataclasses

    from labkit.sim.sweep import SweepResult

    n, d = s.speeds_mm_s.shape
    ps = PointSet(**{fl.name: getattr(s, fl.name) for fl in dataclasses.fields(SweepResult)},
                  foot_rise_um=np.zeros((n, d)), leg_motion_um=np.ones((n, d)), aperiodicity=np.zeros((n, d)),
                  drives=[{}] * n)
    ps.to_h5(tmp_path / "points.h5")
    pts = labkit.open(tmp_path / "points.h5")
    assert pts.kind == "sim_points" and pts.quantity == "freq_hz"
    ds = pts.to_xarray()
    np.testing.assert_array_equal(ds["freq_hz"].values, s.values)
    np.testing.assert_array_equal(ds["leg_motion_um"].values, np.ones((n, d)))
    np.testing.assert_array_equal(ds["speeds_mm_s"].values, ps.speeds_mm_s)


@pytest.mark.parametrize("name", sorted(SCHEMA1_KINDS))
def test_labkit_info_summarises_schema1_files(name):
    from labkit.commands.info import summarise

    s = summarise(SCHEMA1 / name)
    json.dumps(s, default=str)
    assert s["kind"] == SCHEMA1_KINDS[name] and s["schema_version"] == 1
    assert "error" not in s["content"] and s["content"]["kind"] == SCHEMA1_KINDS[name]
