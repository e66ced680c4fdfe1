"""Certificates of the routing answer: MILP-static's walls' cut bound at phase 2's flow
level (:mod:`synthesis.routing.bounds.cut_bound`), with its cheapest candidate completed into a
whole model solution and checked against every row (:func:`cut_proof`, :class:`CutProof`).
Every valid cut set with that flow costs at least the bound, so an answer that meets it is
proven optimal at that level, with or without a search (:func:`with_cut_proof`); a candidate
at the flow upper bound proves phase 1's maximum flow (:func:`test_at_bound`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..graphs.products import Products
from .backends import cpsat
from .model import RoutingModel, model_cut_bound
from .options import MilpOptions
from .phases import FEASIBILITY_TOLERANCE, Phase, guess_solution, phase2_cost, trap_test


def model_arrays(rm: RoutingModel) -> cpsat.ModelArrays:
    """The routing model's matrix and bounds, to check a whole solution against every row."""
    col_lo, col_hi, row_lo, row_hi = rm.model.bounds()
    return cpsat.ModelArrays(rm.model.matrix().tocsr(), row_lo, row_hi, col_lo, col_hi)


def solves_at(arrays: cpsat.ModelArrays, rm: RoutingModel, x: np.ndarray, flow: int) -> bool:
    """Whether ``x`` satisfies every row and bound of the model with flow exactly ``flow``."""
    return arrays.violation(x) <= FEASIBILITY_TOLERANCE and abs(rm.flow_of(x) - flow) <= 0.5


@dataclass(frozen=True)
class CutProof:
    """MILP-static's walls' cut bound at phase 2's flow level (:mod:`synthesis.routing.bounds.cut_bound`:
    every valid cut set with that flow costs at least :attr:`bound`) and its cheapest
    candidate, completed into a model solution and checked (``None``: none passed)."""

    bound: float
    level: int
    x: np.ndarray | None
    candidates: int
    checked: int

    def start(self, x: np.ndarray, cost: np.ndarray) -> np.ndarray:
        """The cheaper of ``x`` and the checked candidate (``x`` on a tie)."""
        if self.x is not None and float(cost @ self.x) < float(cost @ x) - 0.5:
            return self.x
        return x

    def meets(self, x: np.ndarray, cost: np.ndarray) -> bool:
        """Whether ``x`` (a solution of the phase-2 model) costs no more than the bound: then
        it is optimal at this level."""
        value = float(cost @ x)
        if value < self.bound - 0.5:
            raise RuntimeError(f"a test costs {value:.0f}, below the walls' cut bound {self.bound:.0f}: a FlowTest bug")
        return value <= self.bound + 0.5

    def stats(self, cost: np.ndarray, x: np.ndarray, proven: bool) -> dict[str, Any]:
        """What the bound did, for the result's stats."""
        return {
            "level": self.level,
            "bound": self.bound,
            "candidates": self.candidates,
            "checked": self.checked,
            "candidate_cost": None if self.x is None else float(cost @ self.x),
            "proven": proven,
        }


def cut_proof(products: Products, rm: RoutingModel, options: MilpOptions, entries: dict[int, np.ndarray], flow: int) -> CutProof | None:
    """The walls' cut bound at phase 2's level with its cheapest checked candidate, for
    MILP-static (``None`` elsewhere, with ``options.cut_bound`` off, for MILP-agent's places
    objective, or where the bound does not apply). A candidate counts only as a whole model
    solution that satisfies every row of the model (feasibility flows included) with flow
    ``flow`` exactly: the routing heuristic grows it from the candidate's walls (opening any
    of them that separation does not need) and :func:`guess_solution` completes it."""
    groups, me = rm.groups, rm.edges
    cb = model_cut_bound(products, options, groups, me, flow)
    if cb is None:
        return None
    if not np.isfinite(cb.value):
        return CutProof(cb.value, flow, None, 0, 0)  # no cut set has this flow (phase 2: meets() reports the bug)
    cost = phase2_cost(rm, options)
    arrays = model_arrays(rm)
    traps = trap_test(products, groups, entries)
    best: np.ndarray | None = None
    checked = 0
    for walls in cb.candidates:
        guess = replace(me, has_var=me.has_var & walls).guess(products, traps=traps, route_seed=False, fixed_open=rm.reductions.fixed_open)
        if guess.flow != flow:
            continue
        x = guess_solution(products, rm, guess, options)
        if x is None or not solves_at(arrays, rm, x, flow):
            continue
        checked += 1
        if best is None or float(cost @ x) < float(cost @ best) - 0.5:
            best = x
    return CutProof(cb.value, flow, best, len(cb.candidates), checked)


def test_at_bound(products: Products, rm: RoutingModel, options: MilpOptions, entries: dict[int, np.ndarray], upper: int) -> np.ndarray | None:
    """MILP-static, phase 1: a checked candidate of the walls' cut bound at the flow upper bound
    ``upper`` (see :func:`cut_proof`), which proves the maximum flow without a search; ``None``
    where there is none (or the bound does not apply)."""
    if upper < 1:
        return None
    proof = cut_proof(products, rm, options, entries, upper)
    return None if proof is None else proof.x


def with_cut_proof(phase: Phase, proof: CutProof | None, cost: np.ndarray) -> Phase:
    """A phase-2 answer with what the cut bound says of it: optimal when it meets the bound."""
    if proof is None:
        return phase
    proven = proof.meets(phase.x, cost)
    if proven and phase.status != "optimal":
        return Phase(phase.x, "optimal", 0.0, None, proof.stats(cost, phase.x, True))
    return replace(phase, cut_bound=proof.stats(cost, phase.x, proven))
