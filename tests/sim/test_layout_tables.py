"""The scheme's flat workspaces (labkit/sim/scheme.py) are laid out from one table each.

Each table lists (name, size) regions; the module's offsets are unpacked from it. Checked
here, independently of :func:`labkit.sim.scheme.layout`: every name holds the running sum of
the sizes before it, no two regions overlap, every region lies inside its workspace, and the
arrays the kernel allocates have the workspace's size. Also the sub-regions the scheme carves
out of a region (a partial step's parts in W_SM and W_B, the cached inverses' scratch) fit.
"""
from __future__ import annotations

import pytest

from labkit.sim import RobotParams, Shaker
from labkit.sim import model as M
from labkit.sim import scheme as K

TABLES = {"A": (K.A_REGIONS, K.A_SIZE), "LEV": (K.LEV_REGIONS, K.LEV_SIZE), "S": (K.S_REGIONS, K.S_SIZE),
          "W": (K.W_REGIONS, K.W_SIZE), "I": (K.I_REGIONS, K.I_SIZE)}


@pytest.mark.parametrize("name", sorted(TABLES))
def test_every_offset_is_its_tables_running_sum(name):
    regions, size = TABLES[name]
    start = 0
    for key, n in regions:
        assert isinstance(n, int) and n > 0, key
        assert getattr(K, key) == start, key
        start += n
    assert size == start


@pytest.mark.parametrize("name", sorted(TABLES))
def test_no_two_regions_overlap_and_all_lie_inside(name):
    regions, size = TABLES[name]
    spans = sorted((getattr(K, key), getattr(K, key) + n, key) for key, n in regions)
    assert len({key for _, _, key in spans}) == len(spans)          # every name once
    for (_, end, key), (start, _, nxt) in zip(spans, spans[1:]):
        assert end <= start, (key, nxt)
    assert all(0 <= a < b <= size for a, b, _ in spans)


def test_the_kernels_arrays_have_the_workspaces_sizes():
    W, Iw = K.new_scratch()
    assert W.size == K.W_SIZE and Iw.size == K.I_SIZE
    mdl = M.build_model(RobotParams(), Shaker(240, 25))
    P, A = mdl.pack(1e-5)
    assert P.size == K.P_SIZE and A.size == K.A_SIZE
    assert M.rest_state(mdl).size == K.S_SIZE


def test_the_parts_carved_out_of_a_region_fit_in_it():
    size = dict(K.W_REGIONS)
    # partial_system: D_l^-1 (NQ), the Schur complement (NB x NB), u_a for up to NI rows (NB each)
    assert K.NQ + K.NB * K.NB + K.NI * K.NB <= size["W_SM"]
    # its right-hand sides: NB rows of 1 + NR columns; cached_inverse's identity, NC x NC
    assert K.NB * (1 + K.NR) <= size["W_B"] and K.NC * K.NC <= size["W_B"]
    # the small system and the impulse's dense fallback: NI x NI; the cache: NSLOT inverses NC x NC
    assert size["W_AS"] == K.NI * K.NI and size["W_CACHE"] == K.NSLOT * K.NC * K.NC
    assert K.LEV_SIZE * K.NLEV == dict(K.A_REGIONS)["OFF_LEV"]
