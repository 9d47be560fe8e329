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

_registered = False


def unmanaged(a: Any) -> Any:
    """The same array without numba's reference counting: in compiled code a view of ``a``
    whose memory-info (and parent) pointers are null; in plain Python ``a`` itself.

    Why: numba increments and decrements an atomic reference count on every array argument
    of a compiled function it does not inline, and its pruning pass leaves most of these in
    the scheme's functions. On this machine a pair costs ~10 ns. numba skips the count for a
    null memory-info, so the kernel's entry point (:func:`labkit.sim.scheme.integrate`) passes
    its output arrays down as such views (the step's own arrays go as :func:`pointer`).
    The caller must keep ``a`` alive while the view is used (an argument of the compiled
    function is: the Python caller holds it)."""
    return a


def pointer(a: Any) -> Any:
    """The address of an array's data as a typed pointer in compiled code (``ptr[i]`` reads
    and writes element i, nothing else: no shape, no reference count, no negative-index
    wraparound, one machine word per argument instead of an array's seven); in plain Python
    ``a`` itself, indexed the same way. The caller keeps ``a`` alive and indexes it in range;
    ``a`` must be C-contiguous (anything else does not compile)."""
    return a


def _register_intrinsics() -> None:
    """Teach numba :func:`unmanaged` and :func:`pointer` (once, when the first function is
    compiled)."""
    global _registered
    if _registered:
        return
    from numba import types
    from numba.core import cgutils
    from numba.extending import intrinsic, overload

    @intrinsic
    def _null_meminfo(typingctx: Any, arr: Any) -> Any:
        if not isinstance(arr, types.Array):
            return None

        def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
            ary = context.make_array(sig.args[0])(context, builder, value=args[0])
            ary.meminfo = cgutils.get_null_value(ary.meminfo.type)
            ary.parent = cgutils.get_null_value(ary.parent.type)
            return ary._getvalue()

        return arr(arr), codegen

    @overload(unmanaged)
    def _unmanaged(a):  # no annotations: numba compares this signature with the lambda's
        if isinstance(a, types.Array):
            return lambda a: _null_meminfo(a)
        return None

    @intrinsic
    def _data_pointer(typingctx: Any, arr: Any) -> Any:
        # C-contiguous only: element i of a strided array is not at data + i
        if not isinstance(arr, types.Array) or arr.layout != "C":
            return None

        def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
            return context.make_array(sig.args[0])(context, builder, value=args[0]).data

        return types.CPointer(arr.dtype)(arr), codegen

    @overload(pointer)
    def _pointer(a):  # no annotations: numba compares this signature with the lambda's
        if isinstance(a, types.Array) and a.layout == "C":
            return lambda a: _data_pointer(a)
        return None

    _registered = True


def jit(fn: Callable[..., Any]) -> Callable[..., Any]:
    """``numba.njit(cache=True, nogil=True)`` normally (nogil: the virtual lab runs
    simulations in server threads); the identity while :data:`PURE` is set."""
    if PURE:
        return fn
    from numba import njit

    _register_intrinsics()
    return njit(cache=True, nogil=True)(fn)
