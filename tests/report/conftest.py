"""Fixtures of the report tests: the input files of :mod:`report_data`, in a temporary folder."""
from __future__ import annotations

from pathlib import Path

import pytest
from report_data import SHAKER_SPEED, write_fit, write_inchip, write_shaker, write_sim_result, write_sweep, write_track


@pytest.fixture
def inputs(tmp_path: Path) -> dict[str, Path]:
    d = tmp_path / "in"
    d.mkdir()
    files = {"inchip": write_inchip(d / "inchip.h5"), "fit": write_fit(d / "robot.fit.h5"),
             "shaker": write_shaker(d / "shaker.h5"), "sweep": write_sweep(d / "sweep.h5"),
             "sim_200": write_sim_result(d / "sim_200.h5", 200.0, 25.0, "firm_contact"),
             "sim_300": write_sim_result(d / "sim_300.h5", 300.0, 25.0, "jumping")}
    # tracks: four matched to the run's videos, one carrying its own frequency
    for i in range(4):
        s = SHAKER_SPEED[i]
        video = str(d / "videos/p0.mp4") if i == 0 else f"videos/p{i}.mp4"     # absolute, or beside the track
        files[f"track{i}"] = write_track(d / f"track{i}.h5", s, (s - 0.4, s + 0.4), video=video)
    files["track4"] = write_track(d / "track4.h5", 0.0, (-0.05, 0.05), freq_hz=600.0)
    return files
