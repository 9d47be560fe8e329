"""The reference engine: the same :mod:`labkit.sim.scheme` source run as plain Python.

A second copy of ``scheme.py`` is loaded under the name
``labkit.sim._scheme_python`` while :data:`labkit.sim._jit.PURE` is set, so
none of its functions is compiled (its ``ix()`` index marks, the identity in
Python, are dropped from the syntax tree) (see :mod:`labkit.sim._jit` for why one
source serves both engines). About 1000 times slower than the kernel; use it
for short runs and for checking the compiled engine.
"""
from __future__ import annotations

import ast
import importlib.util
import sys
import threading
from pathlib import Path
from types import ModuleType

import numpy as np

from labkit.sim import _jit

_LOCK = threading.Lock()
_NAME = "labkit.sim._scheme_python"


class _DropIx(ast.NodeTransformer):
    def visit_Call(self, node: ast.Call) -> ast.AST:
        self.generic_visit(node)
        if isinstance(node.func, ast.Name) and node.func.id == "ix" and len(node.args) == 1 and not node.keywords:
            return node.args[0]
        return node


def _without_ix(tree: ast.Module) -> ast.Module:
    """The scheme's syntax tree with every ``ix(e)`` replaced by ``e``: in plain Python
    :func:`labkit.sim._jit.ix` is the identity, and its calls, a Python function call per array
    access, would make the reference ~15 % slower than the scheme's arithmetic needs (and
    flatter the kernel/reference ratio of ``bench/sim_bench.py``). Line numbers are kept."""
    return ast.fix_missing_locations(_DropIx().visit(tree))


def scheme_python() -> ModuleType:
    """The plain-Python copy of the scheme (loaded once)."""
    with _LOCK:
        mod = sys.modules.get(_NAME)
        if mod is not None:
            return mod
        path = Path(__file__).with_name("scheme.py")
        spec = importlib.util.spec_from_file_location(_NAME, path)
        assert spec is not None
        mod = importlib.util.module_from_spec(spec)
        code = compile(_without_ix(ast.parse(path.read_text(), str(path))), str(path), "exec")
        _jit.PURE = True
        try:
            exec(code, mod.__dict__)
        finally:
            _jit.PURE = False
        sys.modules[_NAME] = mod
        return mod


def run(P: np.ndarray, A: np.ndarray, state: np.ndarray, mode: np.ndarray, n_steps: int, dt: float, every: int,
        n_skip: int, n_rec: int, ev_cap: int) -> dict[str, np.ndarray]:
    """Integrate with the plain-Python scheme (same outputs as :func:`labkit.sim.kernel.run`)."""
    from labkit.sim.kernel import run_scheme

    return run_scheme(scheme_python(), P, A, state, mode, n_steps, dt, every, n_skip, n_rec, ev_cap)
