"""The decorator that makes :mod:`labkit.sim.scheme` the compiled kernel or the Python reference.

``scheme.py`` is written once. Imported normally, every function is compiled by
numba (``cache=True``: the machine code is kept next to the source). The
reference engine (:mod:`labkit.sim.reference`) loads a second copy of the same
file under another module name while :data:`PURE` is true, and then every
function stays plain Python, calling the other plain functions of its copy.
So the two engines run one scheme, and the reference checks what compilation
may change (integer/float typing, aliasing, the order of floating-point
operations), not a second transcription of the physics: the physics is tested
against laws and closed forms (``tests/sim``).
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

#: True while the reference copy of the scheme is being loaded.
PURE = False


def jit(fn: Callable[..., Any]) -> Callable[..., Any]:
    """``numba.njit(cache=True, nogil=True)`` normally (nogil: the virtual lab runs
    simulations in server threads); the identity while :data:`PURE` is set."""
    if PURE:
        return fn
    from numba import njit

    return njit(cache=True, nogil=True)(fn)
