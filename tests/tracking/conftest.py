"""Fixtures of the tracking tests: one folder of rendered videos per test session."""
from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def video_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("track_videos")
