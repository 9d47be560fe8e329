"""The virtual lab: simulated instruments over real transports, whose physics is the project's own.

>>> from labkit.lab import VirtualLab
>>> with VirtualLab(seed=0) as lab:            # doctest: +SKIP
...     lab.resources["scope"]                  # 'TCPIP0::127.0.0.1::<port>::SOCKET'

See :mod:`labkit.lab.core` for the wiring, :mod:`labkit.lab.physics` for the
models, :mod:`labkit.lab.control` for the control channel.
"""
from labkit.lab.core import SETUPS, VirtualLab
from labkit.lab.physics import SPOTS

__all__ = ["VirtualLab", "SPOTS", "SETUPS"]
