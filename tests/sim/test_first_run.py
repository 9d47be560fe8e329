"""The compiled kernel: compiled once, visibly, and loaded from numba's disk cache by every
later process (real processes; the cold compile on a fresh clone is timed by
bench/first_run_bench.py, it takes minutes)."""
from __future__ import annotations

import json
import subprocess
import sys

PROBE = """
import json
from labkit.sim import RobotParams, Shaker, simulate
from labkit.sim import kernel, scheme
cached = kernel.kernel_cached()
simulate(RobotParams(), Shaker(), duration_s=0.002)
st = scheme.integrate.stats
hits, misses = sum(st.cache_hits.values()), sum(st.cache_misses.values())
print(json.dumps({"cached_before": cached, "hits": hits, "misses": misses}))
"""


def _probe() -> tuple[dict, str]:
    proc = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, timeout=900, check=True)
    return json.loads(proc.stdout.splitlines()[-1]), proc.stderr


def test_a_second_process_loads_the_kernel_from_the_cache_and_says_nothing():
    first, err1 = _probe()              # compiles (and says so) if no process did before
    if first["misses"]:
        assert "compiling the simulator kernel, once" in err1
    second, err2 = _probe()
    assert second == {"cached_before": True, "hits": 1, "misses": 0}
    assert "compiling" not in err2


def test_the_compile_line_comes_before_the_compilation(capsys, monkeypatch):
    """With no compiled signature and an empty cache the line is printed, once per process."""
    from labkit.sim import kernel

    monkeypatch.setattr(kernel, "_compiled", False)
    monkeypatch.setattr(kernel, "kernel_cached", lambda: False)
    monkeypatch.setattr(kernel._scheme, "integrate", type("D", (), {"signatures": []})())
    kernel.announce_compile()
    kernel.announce_compile()
    err = capsys.readouterr().err
    assert err.count("compiling the simulator kernel, once, ~") == 1
