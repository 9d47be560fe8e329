"""Per-point videos under the output policy: an earlier run's are refused without --force, they
are counted in the room check, and each is written aside and renamed into place."""
from __future__ import annotations

import cv2
import h5py
import pytest
from labcfg import shaker_toml, small_tmpfs

from labkit.errors import InputError
from labkit.experiments.runfile import DiskFull
from labkit.experiments.session import run_session
from labkit.lab import VirtualLab


def _rx(lab) -> int:
    return sum(1 for _, _, kind, _ in lab.log if kind == "rx")


@pytest.mark.slow
def test_an_earlier_runs_video_is_refused_without_force_then_replaced_whole(tmp_path):
    cfg = shaker_toml(tmp_path / "s.toml", [150.0], [5.0], video_s=0.2)
    out = tmp_path / "run.h5"
    videos = tmp_path / "run_videos"
    videos.mkdir()
    old = videos / "p00000.mkv"
    old.write_bytes(b"an earlier run's video")
    with VirtualLab(seed=4) as lab:
        before = _rx(lab)
        with pytest.raises(InputError, match="p00000.mkv") as refused:
            run_session("shaker", cfg, out, lab=lab, quiet=True)
        assert "--force" in str(refused.value) and not out.exists()
        assert _rx(lab) == before                      # refused before the first byte
        summary = run_session("shaker", cfg, out, lab=lab, quiet=True, force=True)
    assert summary["status"] == "complete"
    cap = cv2.VideoCapture(str(old))
    frames = 0
    while cap.read()[0]:
        frames += 1
    cap.release()
    assert frames >= 3                                 # the new video, whole
    with h5py.File(out, "r") as f:
        assert f["points/video"].asstr()[0] == "run_videos/p00000.mkv"
    assert sorted(p.name for p in videos.iterdir()) == ["p00000.mkv"]     # no partial file left


def test_videos_are_counted_in_the_room_check(tmp_path):
    """Two points of 0.5 s video (counted 4.6 MB each) do not fit a 6 MB file system: exit 2
    before anything is sent (the videos were not counted: a truncated video and status running)."""
    with small_tmpfs(tmp_path / "small", "6m") as mnt:
        cfg = shaker_toml(tmp_path / "s.toml", [150.0, 200.0], [5.0], video_s=0.5)
        with VirtualLab(seed=4) as lab:
            before = _rx(lab)
            with pytest.raises(DiskFull, match="not enough room for this run"):
                run_session("shaker", cfg, mnt / "run.h5", lab=lab, quiet=True)
            assert _rx(lab) == before
        assert list(mnt.iterdir()) == []
