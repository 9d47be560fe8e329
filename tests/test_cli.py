"""The CLI contract: exit codes, one-line errors, --json as the last stdout line."""
from __future__ import annotations

import h5py
import numpy as np

from clihelpers import last_json, run_cli
from labkit.h5io import SCHEMA_VERSION, put, stamp


def test_help_lists_subcommands():
    proc = run_cli("--help")
    assert "info" in proc.stdout


def test_unknown_subcommand_is_usage_error():
    proc = run_cli("no-such-command", check=2)
    assert "error" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_info_missing_file_exits_2_with_the_path(tmp_path):
    missing = tmp_path / "nothere.h5"
    proc = run_cli("info", str(missing), "--json", check=2)
    assert str(missing) in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
    assert last_json(proc)["ok"] is False


def test_info_not_hdf5_exits_2(tmp_path):
    bogus = tmp_path / "bogus.h5"
    bogus.write_text("this is not HDF5")
    proc = run_cli("info", str(bogus), check=2)
    assert "not a readable HDF5 file" in proc.stderr


def test_info_summarises_datasets_with_units(tmp_path):
    path = tmp_path / "x.h5"
    with h5py.File(path, "w") as f:
        stamp(f, "example")
        put(f.create_group("data"), "speed_mm_s", np.arange(3.0), "mm/s")
    summary = last_json(run_cli("info", str(path), "--json"))
    assert summary["kind"] == "example"
    assert summary["schema_version"] == SCHEMA_VERSION
    assert {"name": "data/speed_mm_s", "shape": [3], "dtype": "float64", "units": "mm/s"} in summary["datasets"]


def test_bad_toml_names_file_and_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("a = [1, 2\n")
    proc = run_cli("info", str(bad), check=2)
    assert "bad.toml" in proc.stderr and "not valid TOML" in proc.stderr


def test_output_in_a_missing_folder_is_bad_input_not_a_traceback(tmp_path):
    out = tmp_path / "no_such_folder" / "run.h5"
    proc = run_cli("simulate", "shaker", "--freq-hz", "240", "--amp-um", "25", "--duration-s", "0.05",
                   "--out", str(out), check=2)
    assert "Traceback" not in proc.stderr
    assert "no_such_folder" in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
