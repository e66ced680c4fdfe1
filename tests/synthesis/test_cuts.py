"""The two sides of a minimum cut read off a maximum flow (synthesis/graphs/cuts.py), held
to their definition on random graphs: each side's outgoing capacity is the flow's value,
the smallest side lies inside the largest, and no minimum cut has a smaller source side
(checked by brute force on small graphs)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import maximum_flow

from synthesis.graphs.cuts import min_cut, sink_side, source_side


def _random_network(seed: int, n: int) -> sp.csr_matrix:
    rng = np.random.default_rng(seed)
    m = rng.integers(n, 3 * n)
    u, v = rng.integers(0, n, m), rng.integers(0, n, m)
    keep = u != v
    cap = sp.csr_matrix((rng.integers(1, 5, int(keep.sum())), (u[keep], v[keep])), shape=(n, n))
    cap.sum_duplicates()
    return cap.astype(np.int32)


def _out_capacity(cap: sp.csr_matrix, side: np.ndarray) -> int:
    coo = cap.tocoo()
    return int(coo.data[side[coo.row] & ~side[coo.col]].sum())


@pytest.mark.parametrize("seed", range(40))
def test_both_sides_are_minimum_cuts_and_extreme(seed: int) -> None:
    n = 7
    cap = _random_network(seed, n)
    s, t = 0, n - 1
    res = maximum_flow(cap, s, t)
    small = source_side(cap, res.flow, s)
    large = ~sink_side(cap, res.flow, t)
    value, side = min_cut(cap, s, t)
    assert value == res.flow_value and np.array_equal(side, small)
    assert small[s] and not large[t] and np.all(large[small])
    assert _out_capacity(cap, small) == value == _out_capacity(cap, large)
    # brute force: every source side of a minimum cut lies between the two
    others = [v for v in range(n) if v not in (s, t)]
    for bits in itertools.product([False, True], repeat=len(others)):
        side_ = np.zeros(n, dtype=bool)
        side_[s] = True
        side_[others] = bits
        c = _out_capacity(cap, side_)
        assert c >= value
        if c == value:
            assert np.all(side_[small]) and np.all(large[side_])
