"""Independent checks of a synthesized test (Theorems 1 and 2 of the method).

Nothing here reads the MILP: the checks take the restrictions an environment will
enforce and search the product graphs directly.

* **bypass flow** (Theorem 1): the maximum flow from ``Src`` to ``Tgt`` on G without
  the edges ``E(I)`` and without the restricted edges must be 0, i.e. no execution
  reaches the goal without passing the test objective;
* **flow**: the maximum flow on G without the restricted edges equals the MILP's F;
* **feasibility** (Theorem 2): from every history's kept entry nodes, ``Tgt_sys`` is
  reachable on G_sys over moves not restricted under that history. Static walls are
  on the map the system sees from its first step, so an entry node is kept when
  ``Tgt_sys`` is reachable from it on that map (T without the walls): one the walls
  alone doom is entered by no correct system. For a purely static test this leaves
  ``F >= 1`` as its feasibility, as docs/method.md §5 says;
* **no trap in the closed loop**: no configuration reachable under the restrictions
  loses, through them, a way to the goal it would otherwise have.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import maximum_flow

from ..graphs.products import Products, coreachable, reachable
from ..model.errors import CheckFailed
from ..model.strategy import TestStrategy


def restricted_edges(products: Products, strategy: TestStrategy) -> np.ndarray:
    """``bool[m]``: the edges of G blocked by the strategy (history of the tail)."""
    g = products.virtual
    out: np.ndarray = strategy.blocked[g.hist[g.src], g.move]
    return out


def max_flow(n: int, src: np.ndarray, dst: np.ndarray, source: int, targets: np.ndarray) -> int:
    """Maximum flow with unit edge capacities from ``source`` to the set ``targets``."""
    if targets[source]:
        return 0
    t = np.flatnonzero(targets)
    sink = n
    big = max(int(src.size), 1)
    rows = np.concatenate([src, t])
    cols = np.concatenate([dst, np.full(t.size, sink)])
    caps = np.concatenate([np.ones(src.size, dtype=np.int32), np.full(t.size, big, dtype=np.int32)])
    keep = rows != cols
    cap = sp.csr_matrix((caps[keep], (rows[keep], cols[keep])), shape=(n + 1, n + 1))
    cap.sum_duplicates()
    return int(maximum_flow(cap, source, sink).flow_value)


def bypass_flow(products: Products, blocked_edges: np.ndarray) -> int:
    """Max flow ``Src -> Tgt`` on G without ``E(I)`` and without ``blocked_edges``."""
    g = products.virtual
    keep = ~products.touches_intermediate & ~blocked_edges
    return max_flow(g.n_nodes, g.src[keep], g.dst[keep], g.initial, products.target)


def routed_flow(products: Products, blocked_edges: np.ndarray) -> int:
    """Max flow ``Src -> Tgt`` on G without ``blocked_edges``."""
    g = products.virtual
    keep = ~blocked_edges
    return max_flow(g.n_nodes, g.src[keep], g.dst[keep], g.initial, products.target)


def trapped_entries_of(products: Products, blocked: np.ndarray, entries: dict[int, np.ndarray]) -> dict[int, np.ndarray]:
    """Per history, the given G_sys nodes with no way to ``Tgt_sys`` under that history's restrictions.

    ``blocked[q, m]`` says whether move ``m`` is restricted under history ``q``.
    """
    gs = products.system
    out: dict[int, np.ndarray] = {}
    for q, nodes in entries.items():
        keep = ~blocked[q, gs.move]
        ok = coreachable(gs.n_nodes, gs.src[keep], gs.dst[keep], products.system_target)
        bad = nodes[~ok[nodes]]
        if bad.size:
            out[int(q)] = bad
    return out


def entries_on_map(products: Products, static_obstacles: np.ndarray) -> dict[int, np.ndarray]:
    """Per history, the kept entry nodes (of G_sys) that can reach ``Tgt_sys`` on the map
    the system sees: T without the static walls ``static_obstacles`` (``bool[n_moves]``)."""
    gs = products.system
    keep = ~static_obstacles[gs.move]
    ok = coreachable(gs.n_nodes, gs.src[keep], gs.dst[keep], products.system_target)
    out = {q: nodes[ok[nodes]] for q, nodes in products.kept_entries.items()}
    return {q: nodes for q, nodes in out.items() if nodes.size}


def trapped_entries(products: Products, strategy: TestStrategy) -> dict[int, np.ndarray]:
    """Per history, entry nodes (of G_sys) kept on the map with no way to ``Tgt_sys``
    under that history's restrictions."""
    return trapped_entries_of(products, strategy.blocked, entries_on_map(products, strategy.static_obstacles))


def trapped_configurations(products: Products, blocked: np.ndarray) -> np.ndarray:
    """Nodes of G where the closed loop traps the system.

    Trapped: reachable from ``Src`` under the restrictions (applied with the history of
    each move's tail), able to reach ``Tgt`` in G without restrictions (the system has
    not doomed itself), yet unable to under the restrictions.
    """
    g = products.virtual
    keep = ~blocked[g.hist[g.src], g.move]
    src, dst = g.src[keep], g.dst[keep]
    reach = reachable(g.n_nodes, src, dst, np.arange(g.n_nodes) == g.initial)
    can = coreachable(g.n_nodes, g.src, g.dst, products.target)
    can_restricted = coreachable(g.n_nodes, src, dst, products.target)
    return np.flatnonzero(reach & can & ~can_restricted)


@dataclass(frozen=True)
class CheckReport:
    """Outcome of the checks; ``ok`` when every one holds."""

    bypass_flow: int
    flow: int
    expected_flow: int
    trapped: dict[int, np.ndarray] = field(default_factory=dict)
    trapped_nodes: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    closed_loop: bool = False

    @property
    def ok(self) -> bool:
        return (
            self.bypass_flow == 0
            and self.flow == self.expected_flow
            and self.flow >= 1
            and not self.trapped
            and (self.trapped_nodes.size == 0 or not self.closed_loop)
        )

    def problems(self) -> list[str]:
        msgs = []
        if self.bypass_flow:
            msgs.append(f"bypass flow is {self.bypass_flow}, not 0: some execution avoids the test objective")
        if self.flow != self.expected_flow:
            msgs.append(f"flow under the restrictions is {self.flow}, the MILP said {self.expected_flow}")
        if self.flow < 1:
            msgs.append("no execution reaches the goal under the restrictions")
        for q, nodes in self.trapped.items():
            msgs.append(f"history q{q}: {nodes.size} entry node(s) have no way to the goal")
        if self.trapped_nodes.size:
            msgs.append(f"{self.trapped_nodes.size} reachable configuration(s) are trapped by the restrictions")
        return msgs


def check_test(
    products: Products,
    strategy: TestStrategy,
    expected_flow: int,
    raise_on_failure: bool = True,
    closed_loop: bool = False,
) -> CheckReport:
    """Run every check; raise :class:`CheckFailed` (a FlowTest bug) if one fails.

    Trapped configurations off entry nodes are always counted in the report; they fail
    it only with ``closed_loop=True`` (docs/method.md §5 does not forbid them).

    Examples
    --------
    >>> from synthesis import load_problem, synthesize
    >>> from synthesis.checks.verify import check_test
    >>> test = synthesize(load_problem("small-reactive"))
    >>> report = check_test(test.products, test.strategy, expected_flow=test.routing.flow)
    >>> report.ok, report.bypass_flow, report.flow
    (True, 0, 2)
    """
    blocked = restricted_edges(products, strategy)
    report = CheckReport(
        bypass_flow=bypass_flow(products, blocked),
        flow=routed_flow(products, blocked),
        expected_flow=expected_flow,
        trapped=trapped_entries(products, strategy),
        trapped_nodes=trapped_configurations(products, strategy.blocked),
        closed_loop=closed_loop,
    )
    if raise_on_failure and not report.ok:
        raise CheckFailed("synthesized test failed its checks: " + "; ".join(report.problems()))
    return report
