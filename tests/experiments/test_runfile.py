"""Run files: layout, units on every dataset, trimming a cut point on resume, config matching."""
from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from clihelpers import REPO, last_json, run_cli
from labkit.errors import InputError
from labkit.experiments import runfile as rf
from labkit.experiments.config import comparable, load_inchip, load_shaker

INCHIP = REPO / "sample_data" / "inchip.toml"
SHAKER = REPO / "sample_data" / "shaker.toml"


def _inchip_point(run, i, loc, f):
    run.add_location_rows(loc, {"freq_hz": f, "frf": 1 + 2j, "quality": 0.99, "drive_v": 2 + 0j,
                                "velocity_mm_s": 2 + 4j, "point_index": i})
    run.end_point(i, {"location": loc, "freq_hz": f, "status": "ok", "reason": "", "time_unix_s": 1.0,
                      "duration_s": 0.1})


def test_inchip_layout_units_and_info(tmp_path):
    cfg = load_inchip(INCHIP)
    path = tmp_path / "run.h5"
    with rf.RunFile.create(path, cfg, comparable(cfg), 180) as run:
        run.set_instrument("funcgen", "33500B", "TCPIP0::x::1::SOCKET", {"identity": "K,33522B"})
        for i, f in enumerate((300.0, 310.0)):
            _inchip_point(run, i, "body", f)
        run.end_point(2, {"location": "body", "freq_hz": 320.0, "status": "interlock",
                          "reason": "vibrometer over-range", "time_unix_s": 2.0, "duration_s": 0.1})
        run.event("drive off (interlock)")
        run.finish("complete")
    with h5py.File(path, "r") as f:
        assert f.attrs["kind"] == "run_inchip" and f.attrs["method"] == "stepped"
        assert f.attrs["status"] == "complete" and f.attrs["config_toml"] == INCHIP.read_text()
        assert json.loads(f.attrs["versions_json"])["labkit"]
        assert f["locations/body/frf"].dtype == np.complex128
        assert f["locations/body/frf"].attrs["units"] == "(mm/s)/V"
        assert list(f["locations/body/freq_hz"][...]) == [300.0, 310.0]
        assert list(f["points/status"].asstr()[...]) == ["ok", "ok", "interlock"]
        assert json.loads(f["instruments/funcgen"].attrs["snapshot_json"])["identity"] == "K,33522B"
        missing = []
        f.visititems(lambda n, o: missing.append(n) if isinstance(o, h5py.Dataset) and "units" not in o.attrs else None)
        assert missing == []
    info = last_json(run_cli("info", str(path), "--json"))
    assert info["kind"] == "run_inchip" and info["attrs"]["status"] == "complete"
    assert {"name": "locations/knee/frf", "shape": [0], "dtype": "complex128", "units": "(mm/s)/V"} in info["datasets"]
    assert rf.summary(path)["points_ok"] == 2 and rf.summary(path)["points_interlocked"] == 1


def test_resume_trims_a_cut_point_and_refuses_another_config(tmp_path):
    cfg = load_inchip(INCHIP)
    path = tmp_path / "run.h5"
    run = rf.RunFile.create(path, cfg, comparable(cfg), 180)
    _inchip_point(run, 0, "body", 300.0)
    # a point cut between its data rows and its index (what SIGKILL could leave)
    run.add_location_rows("body", {"freq_hz": 310.0, "frf": 0j, "quality": 0.0, "drive_v": 1 + 0j,
                                   "velocity_mm_s": 0j, "point_index": 1})
    run.f.flush()
    run.close()
    with pytest.raises(InputError, match="different config"):
        other = load_inchip(INCHIP).__class__(**{**load_inchip(INCHIP).__dict__, "amp_vpp": 3.0})
        rf.RunFile.resume(path, other, comparable(other))
    with rf.RunFile.resume(path, cfg, comparable(cfg)) as run:
        assert run.done == {0: "ok"}
        assert run.f["locations/body/freq_hz"].shape == (1,)
        _inchip_point(run, 1, "body", 310.0)
    pts = rf.read_points(path)
    assert list(pts["index"]) == [0, 1]
    with pytest.raises(InputError, match="run_shaker"):
        s = load_shaker(SHAKER)
        rf.RunFile.resume(path, s, comparable(s))


def test_create_refuses_to_overwrite(tmp_path):
    cfg = load_inchip(INCHIP)
    path = tmp_path / "run.h5"
    path.write_bytes(b"")
    with pytest.raises(InputError, match="already exists"):
        rf.RunFile.create(path, cfg, comparable(cfg), 1)


def test_a_long_run_holds_bounded_caches_and_no_new_objects(tmp_path):
    """Memory flat per point, by its causes (the RSS slope itself: bench/memory_bench.py): a run
    file is written with HDF5's chunk cache and metadata cache bounded, the metadata cache stays
    under its cap while thousands of points (and their strings) are written, and no HDF5
    object is left open per point. With h5py's defaults the chunk cache was 8 MiB a dataset
    and the metadata cache held 400 KB after these points (its cap 2 MiB, growing to 32 MiB)."""
    cfg = load_inchip(INCHIP)
    path = tmp_path / "run.h5"
    with rf.RunFile.create(path, cfg, comparable(cfg), 3000) as run:
        assert run.f.id.get_access_plist().get_cache()[2] == rf.CHUNK_CACHE_BYTES
        _inchip_point(run, 0, "body", 300.0)
        run.event("drive on")
        opened = h5py.h5f.get_obj_count(run.f.id, h5py.h5f.OBJ_ALL)
        for i in range(1, 3000):
            _inchip_point(run, i, "body", 300.0 + i)
            run.event("drive off (between points)")
        assert h5py.h5f.get_obj_count(run.f.id, h5py.h5f.OBJ_ALL) == opened
        assert run.done == {}                       # what was finished at open, not a per-point record
        chunks = []
        run.f.visititems(lambda n, o: chunks.append(o.chunks[0] * o.dtype.itemsize)
                         if isinstance(o, h5py.Dataset) and o.chunks else None)
        # the chunk being appended to fits, and little more is kept (64 KiB still grew for 4000 points)
        assert max(chunks) <= rf.CHUNK_CACHE_BYTES <= 2 * max(chunks)
    with rf.RunFile.resume(path, cfg, comparable(cfg)) as run:
        assert len(run.done) == 3000
