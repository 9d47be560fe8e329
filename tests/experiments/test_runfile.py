"""Run files: layout, units on every dataset, trimming a cut point on resume, config matching."""
from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
import xarray as xr

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
    file is written with HDF5's chunk cache and metadata cache bounded, what the metadata cache
    holds stays far under its cap while thousands of points (and their text) are written (so
    HDF5 never writes metadata between flushes to make room), and no HDF5 object is left open
    per point. With variable-length strings (layout 2) the metadata cache held 400 KB after
    these points and grew on with every string (its cap 2 MiB, growing to 32 MiB)."""
    cfg = load_inchip(INCHIP)
    path = tmp_path / "run.h5"
    with rf.RunFile.create(path, cfg, comparable(cfg), 3000) as run:
        assert run.f.id.get_access_plist().get_cache()[2] == rf.CHUNK_CACHE_BYTES
        assert run.f.id.get_mdc_config().max_size == rf.METADATA_CACHE_BYTES
        _inchip_point(run, 0, "body", 300.0)
        run.event("drive on")
        opened = h5py.h5f.get_obj_count(run.f.id, h5py.h5f.OBJ_ALL)
        for i in range(1, 3000):
            _inchip_point(run, i, "body", 300.0 + i)
            run.event("drive off (between points)")
            if i % 500 == 0:
                assert run.f.id.get_mdc_size()[2] < rf.METADATA_CACHE_BYTES / 4, i
        assert h5py.h5f.get_obj_count(run.f.id, h5py.h5f.OBJ_ALL) == opened
        assert run.done == {}                       # what was finished at open, not a per-point record
        chunks = []
        run.f.visititems(lambda n, o: chunks.append(o.chunks[0] * o.dtype.itemsize)
                         if isinstance(o, h5py.Dataset) and o.chunks else None)
        # the chunk being appended to fits, and little more is kept (64 KiB still grew for 4000 points)
        assert max(chunks) <= rf.CHUNK_CACHE_BYTES <= 2 * max(chunks)
    with rf.RunFile.resume(path, cfg, comparable(cfg)) as run:
        assert run.f.id.get_mdc_config().max_size == rf.METADATA_CACHE_BYTES
        assert len(run.done) == 3000


def test_a_copy_taken_between_two_flushes_holds_every_completed_point(tmp_path):
    """What a SIGKILL leaves at an instant between two flushes is the file's bytes as they are
    then. While 2000 points are written (both caches bounded), a copy taken in the middle of a
    point (its location rows and an event written, its index not) every 40 points opens, passes
    every checksum, reads every event's text and holds exactly the points completed. (Bounding
    the metadata cache with variable-length strings let HDF5 write their global heap between
    flushes, and a kill then left ``/events/text`` unreadable.)"""
    from labkit.files.runs import read_run_file

    cfg = load_inchip(INCHIP)
    path, copy = tmp_path / "run.h5", tmp_path / "copy.h5"
    with rf.RunFile.create(path, cfg, comparable(cfg), 2000) as run:
        for i in range(2000):
            run.add_location_rows("hip", {"freq_hz": 300.0 + i, "frf": 1 + 2j, "quality": 0.99, "drive_v": 2 + 0j,
                                          "velocity_mm_s": 2 + 4j, "point_index": i})
            run.event(f"point {i}: rows written, index not yet")
            if i % 40 == 17:
                copy.write_bytes(path.read_bytes())
                back = read_run_file(copy)           # verifies every dataset's checksum
                assert list(back.points["index"]) == list(range(i)), i
                with h5py.File(copy, "r") as f:
                    text = f["events/text"].asstr()[...]
                assert text[-1] == f"point {i}: rows written, index not yet", (i, text[-1])
            run.end_point(i, {"location": "hip", "freq_hz": 300.0 + i, "status": "ok", "reason": "",
                              "time_unix_s": 1.0, "duration_s": 0.1})


def test_text_is_fixed_length_checksummed_and_cut_at_a_character(tmp_path):
    """Layout 3: every text column is fixed-length UTF-8 with a Fletcher-32 checksum (no global
    heap); longer text is cut at a character boundary and ends in the cut mark; a layout-1 run
    file (variable-length strings) still reads."""
    from labkit.files.runs import read_run_file

    cfg = load_inchip(INCHIP)
    path = tmp_path / "run.h5"
    long_reason = "drive measured 2.685 Vpp, commanded 4 \u00b5" * 20
    with rf.RunFile.create(path, cfg, comparable(cfg), 2) as run:
        run.end_point(0, {"location": "body", "freq_hz": 300.0, "status": "interlock", "reason": long_reason,
                          "time_unix_s": 1.0, "duration_s": 0.1})
        run.event("\u00e9v\u00e9nement " * 100)
        run.finish("complete")
    with h5py.File(path, "r") as f:
        assert f.attrs["schema_version"] == 3
        for name in ("points/status", "points/location", "points/reason", "events/text"):
            assert f[name].dtype.kind == "S" and h5py.check_string_dtype(f[name].dtype).encoding == "utf-8"
            assert f[name].fletcher32, name
        reason = f["points/reason"].asstr()[0]
        event = f["events/text"].asstr()[0]
    assert reason.endswith(rf.CUT_MARK) and long_reason.startswith(reason[:-1])
    assert len(reason.encode()) <= f_width(path, "points/reason")
    assert event.endswith(rf.CUT_MARK) and ("\u00e9v\u00e9nement " * 100).startswith(event[:-1])
    assert list(read_run_file(path).points["reason"]) == [reason]
    with xr.open_dataset(path, engine="h5netcdf", group="events") as ev:     # text, not bytes
        assert ev.text.values.tolist() == [event]
    old = read_run_file(REPO / "tests" / "files" / "schema1" / "inchip_run.h5")
    assert old.points["status"].dtype.kind == "U" and old.complete_points > 0
    # an older file is appended to in its own layout, with HDF5's default metadata cache (its
    # variable-length strings' heap must not be written between flushes)
    older = tmp_path / "older.h5"
    older.write_bytes((REPO / "tests" / "files" / "schema1" / "inchip_run.h5").read_bytes())
    with rf.RunFile(rf.open_for_writing(older, "r+"), older) as run:
        assert run.f.id.get_mdc_config().max_size != rf.METADATA_CACHE_BYTES
        run.event("appended to a layout-1 file \u00b5")
        assert run.f["events/text"].dtype.kind == "O"
    with h5py.File(older, "r") as f:
        assert f["events/text"].asstr()[-1] == "appended to a layout-1 file \u00b5"


def f_width(path, name):
    with h5py.File(path, "r") as f:
        return f[name].dtype.itemsize


def test_no_room_for_the_journal_is_a_clean_disk_full_and_the_file_keeps_every_point(tmp_path):
    """A flush first writes its journal (labkit.h5journal). When the disk has no room for it (here:
    no space set aside for the journal, another file takes every free byte of a 4 MB tmpfs, and a
    point keeps a 400 kB record, more than the journal's earlier flushes used), the flush is a
    DiskFull naming the file, nothing of it reaches the file, and the file, read after the disk
    is freed, holds every point flushed before."""
    import contextlib

    from labcfg import small_tmpfs

    from labkit.files.runs import read_run_file

    cfg = load_inchip(INCHIP)
    with small_tmpfs(tmp_path / "fs", "4m") as mnt:
        path = mnt / "run.h5"
        run = rf.RunFile.create(path, cfg, comparable(cfg), 100, reserve_bytes=1_500_000, journal_bytes=0)
        for i in range(3):
            _inchip_point(run, i, "body", 300.0 + i)
        filler = mnt / "filler"
        with contextlib.suppress(OSError), open(filler, "wb") as fh:
            fh.write(b"\0" * (64 << 20))
        record = np.random.default_rng(0).normal(size=100_000)
        with pytest.raises(rf.DiskFull, match="journal") as err:
            run.add_records("raw", 3, 1e-5, {"velocity_v": (record, "V")})
            _inchip_point(run, 3, "body", 303.0)
        assert str(path) in str(err.value) and run.full
        run.close()
        filler.unlink()
        got = read_run_file(path)
        assert got.complete_points == 3 and list(got.points["index"]) == [0, 1, 2]
