"""What a routing solve returns, whichever backend ran it (HiGHS or CP-SAT, see
:mod:`synthesis.routing.solve`), and the restrictions an answer puts on each history: what
the trap searches read."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..graphs.products import Products
from .options import MilpOptions


@dataclass(frozen=True)
class RoutingResult:
    """The answer of the routing MILP.

    Attributes
    ----------
    status
        ``"optimal"`` only when both phases were proven optimal, else ``"feasible"``.
    flow
        The flow value F.
    cut_edges
        Indices of the edges of G with ``d_e = 1`` (tied copies included).
    cut_group_keys
        The keys of the cut groups (used to exclude this cut set later).
    static_moves_cut
        ``bool`` mask over T's moves: moves blocked for the whole test.
    blocked_places
        Places with ``d_state = 1`` (MILP-agent only).
    mip_gap
        Relative gap of the last phase.
    stats
        Model sizes and times (problem-format.md's names), and ``backend``: the solver
        that produced the answer.
    """

    status: str
    flow: int
    cut_edges: np.ndarray
    cut_group_keys: list[int]
    static_moves_cut: np.ndarray
    blocked_places: np.ndarray
    mip_gap: float
    stats: dict[str, Any]


def required_entries(products: Products, options: MilpOptions) -> dict[int, np.ndarray]:
    """Per history, the G_sys entry nodes the feasibility flows must serve: none for
    MILP-static (its walls are on the map, see :func:`synthesis.routing.solve.solve_routing`),
    else the kept entry nodes of docs/method.md §5."""
    return {} if options.mode == "static" else products.kept_entries


def blocked_by(products: Products, result: RoutingResult) -> np.ndarray:
    """``bool[n_hist, n_moves]``: the moves a routing answer restricts under each history."""
    out: np.ndarray = blocked_of_edges(products, result.cut_edges) | result.static_moves_cut[None, :]
    return out


def blocked_of_edges(products: Products, edges: np.ndarray) -> np.ndarray:
    """``bool[n_hist, n_moves]``: the moves cut edges of G restrict, under the history of their tail."""
    g = products.virtual
    blocked = np.zeros((g.n_hist, products.ts.n_moves), dtype=bool)
    blocked[g.hist[g.src[edges]], g.move[edges]] = True
    return blocked
