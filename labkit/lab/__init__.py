"""The virtual lab: simulated instruments over real transports, whose physics is the project's own.

>>> from labkit.lab import VirtualLab
>>> with VirtualLab(seed=0) as lab:            # doctest: +SKIP
...     lab.resources["scope"]                  # 'TCPIP0::127.0.0.1::<port>::SOCKET'

See :mod:`labkit.lab.core` for the wiring, :mod:`labkit.lab.physics` for the
models, :mod:`labkit.lab.control` for the control channel.
"""
from __future__ import annotations

from typing import Any

__all__ = ["VirtualLab", "SPOTS", "SETUPS"]


def __getattr__(name: str) -> Any:
    # Lazy: importing labkit.lab.render (the tracker's renderer) must not start
    # the simulator and servers' imports.
    if name in ("VirtualLab", "SETUPS"):
        from labkit.lab import core
        return getattr(core, name)
    if name == "SPOTS":
        from labkit.lab.physics import SPOTS
        return SPOTS
    raise AttributeError(f"module 'labkit.lab' has no attribute {name!r}")
