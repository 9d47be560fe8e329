"""`labkit info` on the sidecar files labkit writes (figures, reports, JSON, UFF) and on configs."""
from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from clihelpers import REPO, last_json, run_cli
from labkit.commands.info import summarise


def test_png_figure_size_from_its_header(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(3, 2), dpi=50)
    fig.savefig(tmp_path / "f.png")
    plt.close(fig)
    s = summarise(tmp_path / "f.png")
    assert s["format"] == "png" and (s["content"]["width_px"], s["content"]["height_px"]) == (150, 100)


def test_json_sidecar_keys(tmp_path):
    p = tmp_path / "cal.calibration.json"
    p.write_text(json.dumps({"out": "cal.toml", "parameters": {"c_r": {}}}))
    c = summarise(p)["content"]
    assert c["keys"] == ["out", "parameters"] and "calibrate" in c["kind"]


def test_html_report_title_sections_figures(tmp_path):
    p = tmp_path / "report.html"
    p.write_text("<html><head><title>Robot 7</title></head><body><section><img src='data:,'></section>"
                 "<section><figure><svg viewBox='0 0 1 1'></svg></figure><svg></svg></section></body></html>")
    c = summarise(p)["content"]
    assert (c["title"], c["sections"], c["figures"]) == ("Robot 7", 2, 3)


def test_track_csv_and_video_summaries_read_what_the_files_say(tmp_path):
    """The CSV's header carries the scale (and, from this version, the speed); an MKV's container
    rate field is its 1 ms time base, not the frame rate: the timestamps give the rate."""
    from clihelpers import REPO

    c = summarise(REPO / "sample_data" / "shaker_240hz_track.csv")["content"]
    assert 0.04 < c["mm_per_px"] < 0.06 and c["source_video"].endswith("shaker_240hz.mkv")
    p = tmp_path / "t.csv"
    p.write_text("# labkit track of v.mkv; mm_per_px=0.05; mean_speed_mm_s=18.7; speed_ci_mm_s=18.5,18.9; "
                 "quality: 0 ok, 1 degraded\nt_s,x_mm,y_mm\n0,1,2\n0.1,1,3.87\n")
    c = summarise(p)["content"]
    assert (c["mean_speed_mm_s"], c["speed_ci_mm_s"], c["mm_per_px"]) == (18.7, [18.5, 18.9], 0.05)
    v = summarise(REPO / "sample_data" / "shaker_240hz.mkv")["content"]
    with h5py.File(REPO / "sample_data" / "shaker_240hz_track.h5") as f:
        n = f["t_s"].shape[0]                            # the committed track holds every frame
    assert v["frames"] == n and abs(v["fps"] - (n - 1) / v["duration_s"]) < 0.05 * v["fps"]
    assert "1000 (the container's rate field" in str(v["fps_container"])


def test_uff_datasets_by_type(tmp_path):
    block = ["    -1", "    58", "header", "    -1"]
    p = tmp_path / "robot.fit.uff"
    p.write_text("\n".join(block * 3 + ["    -1", "    55", "modes", "    -1"]) + "\n")
    assert summarise(p)["content"]["datasets_by_type"] == {"58": 3, "55": 1}


def test_info_cli_on_a_config_and_a_bad_png(tmp_path):
    s = last_json(run_cli("info", str(REPO / "sample_data" / "shaker.toml"), "--json"))
    assert s["content"]["kind"] == "config_shaker" and s["content"]["instruments"]["funcgen"]
    bad = tmp_path / "x.png"
    bad.write_bytes(np.zeros(30, np.uint8).tobytes())
    proc = run_cli("info", str(bad), check=2)
    assert "x.png" in proc.stderr and "PNG" in proc.stderr


def test_a_file_of_another_kind_is_named_with_what_labkit_reads(tmp_path):
    p = tmp_path / "notes.md"
    p.write_text("# notes\n")
    proc = run_cli("info", str(p), check=2)
    assert "notes.md" in proc.stderr and "not a file labkit writes" in proc.stderr and "HDF5" in proc.stderr


WRITER = """
import sys, time, h5py
from labkit.experiments.locks import lock_run
from labkit.h5io import stamp
path = sys.argv[1]
with lock_run([], path, "cfg.toml"), h5py.File(path, "w") as f:   # a run's lock, the file open for writing
    stamp(f, "run_inchip")
    f.flush()
    print("ready", flush=True)
    time.sleep(60)
"""


def test_info_names_the_pid_and_host_of_the_run_writing_the_file(tmp_path):
    import socket
    import subprocess
    import sys

    out = tmp_path / "run.h5"
    writer = subprocess.Popen([sys.executable, "-c", WRITER, str(out)], stdout=subprocess.PIPE, text=True)
    try:
        assert writer.stdout is not None and writer.stdout.readline().strip() == "ready"
        s = summarise(out)
        assert s["being_written_by"]["pid"] == writer.pid
        assert s["being_written_by"]["host"] == socket.gethostname()
        assert f"being written by PID {writer.pid} on {socket.gethostname()}" in s["being_written"]
        j = last_json(run_cli("info", str(out), "--json"))
        assert j["being_written_by"]["pid"] == writer.pid and j["format"] == "hdf5"
        text = run_cli("info", str(out)).stdout
        assert f"being written by PID {writer.pid}" in text and "when that run has ended" in text
        # labkit.open (every reader) names the writer too, with a clear error, not an HDF5 one
        import labkit
        from labkit.errors import InputError

        with pytest.raises(InputError) as e:
            labkit.open(out)
        assert f"being written by PID {writer.pid} on {socket.gethostname()}" in str(e.value)
    finally:
        writer.kill()
        writer.wait()
    # the writer gone (its lock dropped by the kernel), the same file is an ordinary file again
    s = summarise(out)
    assert "being_written_by" not in s and s["kind"] == "run_inchip"
