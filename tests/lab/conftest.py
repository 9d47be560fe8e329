"""Fixtures of the virtual-lab tests: a running lab and raw-socket clients."""
from __future__ import annotations

import pytest
from labhelpers import Raw

from labkit.lab import VirtualLab


@pytest.fixture
def lab():
    with VirtualLab(seed=0) as lab:
        yield lab


@pytest.fixture
def raw(lab):
    opened: list[Raw] = []

    def connect(name: str, timeout_s: float = 5.0) -> Raw:
        client = Raw(lab.resources[name], timeout_s)
        opened.append(client)
        return client

    yield connect
    for client in opened:
        client.close()
