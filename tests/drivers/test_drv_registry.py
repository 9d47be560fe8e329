"""Opening instruments by model name."""
from __future__ import annotations

import socket

import pytest

from labkit.drivers.funcgen import Keysight33500B, RigolDG1000Z
from labkit.drivers.registry import driver_class, model_names, open_instrument
from labkit.drivers.scope import InfiniiVision
from labkit.drivers.testing import _SocketPeer, connect_exchanges
from labkit.drivers.vibrometer import OFV5000
from labkit.errors import ConfigError, InstrumentError


def test_model_names_and_aliases():
    assert {"33220A", "33500B", "DG1000Z", "InfiniiVision", "DS1000Z", "OFV-3001",
            "OFV-5000"} <= set(model_names())
    assert driver_class("33522B") is Keysight33500B
    assert driver_class("dg1022z") is RigolDG1000Z
    assert driver_class("ofv 5000") is OFV5000
    assert driver_class("InfiniiVision") is InfiniiVision
    with pytest.raises(ConfigError, match="unknown instrument model"):
        driver_class("HP 8116A")


def test_open_instrument_over_loopback():
    peer = _SocketPeer(connect_exchanges(Keysight33500B, "Keysight Technologies,33522B,MY1,4"))
    peer.start()
    fg = open_instrument("33500B", peer.resource, timeout_s=0.5, channel=2)
    try:
        assert isinstance(fg, Keysight33500B) and fg.channel == 2
        assert fg.identity.startswith("Keysight")
    finally:
        fg.close()
        peer.driver_closed.set()
        peer.join(5)
    assert not peer.failures


def test_open_instrument_unreachable():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    with pytest.raises(InstrumentError):
        open_instrument("InfiniiVision", f"TCPIP0::127.0.0.1::{port}::SOCKET", timeout_s=0.3)


def test_open_file_camera_by_model(tmp_path):
    import cv2
    import numpy as np

    path = tmp_path / "v.avi"
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (32, 24))
    for i in range(3):
        w.write(np.full((24, 32, 3), 60 * i, np.uint8))
    w.release()
    cam = open_instrument("file", str(path), name="camera", timeout_s=1.0)
    try:
        assert cam.name == "camera"
        assert [round(t, 6) for _, t in cam.frames()] == [0.0, 0.1, 0.2]
    finally:
        cam.close()
