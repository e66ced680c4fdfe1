"""The rules that read the built routing model and pick how it is solved: which backend
``"auto"`` runs (:func:`auto_backend`) and how the feasibility flows' closing rows are written
(:func:`per_cut_flow_rows`). Each is a function of the built model and the options only, so the
choice, and with it the answer, is the same on every machine with the locked install."""

from __future__ import annotations

from ..model import RoutingModel
from ..options import MilpOptions
from . import cpsat

AUTO_CPSAT_ROWS: dict[str, tuple[int, int]] = {"static": (200, 15_000), "reactive": (200, 2_500)}
"""Per routing mode, the model sizes (rows, inclusive) at which ``"auto"`` runs CP-SAT; HiGHS
elsewhere and in the other modes. Measured per model kind on the 5x5 random grid study's
instances (docs/benchmarks.md, "auto's backend rule per model kind"; seeds 0-2 of all nine
cells, one worker each, 30 s each, measured under load, so CPU seconds and proofs compared):

* static, 259-13,310 rows (safety to reaction |AP| = 7): CP-SAT proved 24 of 27, HiGHS 19,
  CP-SAT in 0.13-3.9 CPU s wherever it proved (HiGHS 0.03-17.8 s on the same ones);
  mars-exploration (21,515 rows) stays on HiGHS: neither proves its fewest cuts, and its
  shipped artifact is HiGHS's under a node limit.
* reactive, 300-2,026 rows (safety, reachability |AP| = 2, 3, reaction |AP| = 3): CP-SAT
  proved 18 of 18 in 0.13-1.1 CPU s, HiGHS 17 in 0.02-7.0; from 2,706 rows (reachability
  |AP| = 4, 2,706-2,830; reaction |AP| = 5 and 7, 8,887-43,166) HiGHS proved 3 of 9 and CP-SAT
  none (also session 8: CP-SAT 2 of 14 on reachability |AP| = 4). The edge lies in the
  measured gap 2,046-2,706.
* below 200 rows (the built-ins small-reactive, example1, beaver-rescue: 84-153 rows) HiGHS
  answers in 0.03 CPU s, a CP-SAT child (start, model transfer, solve) in 0.11-0.14.

The rule reads the built model only, so the choice, and with it the answer, is the same on
every machine with the locked install. Agent problems (mode ``"mixed"``, many small MILPs)
stay on HiGHS."""


AUTO_CPSAT_MODES: tuple[str, ...] = tuple(AUTO_CPSAT_ROWS)
"""The routing modes in which ``"auto"`` may run CP-SAT (agent problems, mode ``"mixed"``, stay on HiGHS)."""


def auto_backend(rm: RoutingModel, options: MilpOptions) -> str:
    """The backend ``"auto"`` runs on a built model (see :data:`AUTO_CPSAT_ROWS`: by mode and
    rows); HiGHS when OR-Tools is missing. A function of the model and options only, so the choice, and with
    it the answer, is the same on every machine with the locked install."""
    lo, hi = AUTO_CPSAT_ROWS.get(options.mode, (1, 0))
    if lo <= rm.model.n_row <= hi and cpsat.available():
        return "cpsat"
    return "highs"


PER_CUT_MIN_ROWS = 20_000
"""MILP-reactive models on HiGHS with at least this many rows (written per flow edge) get the
feasibility flows' closing rows per cut column (:func:`per_cut_flow_rows`). Measured on the
5x5 random grids' reaction |AP| = 7 reactive models (36,647-43,676 rows, 23,000-25,000 per
cut column; docs/benchmarks.md, "Session 11 (issue 18)"); below, nothing was measured
(reaction |AP| = 5: about 9,000 rows; reachability |AP| = 4: about 2,800), so those models
keep method.md's rows and their answers."""


def per_cut_flow_rows(rm: RoutingModel, options: MilpOptions) -> bool:
    """Whether ``"auto"`` writes the feasibility flows' closing rows per cut column
    (:func:`synthesis.routing.model._add_feasibility` proves the answers the same): on
    HiGHS, for MILP-reactive models of at least :data:`PER_CUT_MIN_ROWS` rows built per flow
    edge. A function of the built model and the options only, so the choice is the same on
    every machine."""
    return (
        options.backend == "highs"
        and options.mode == "reactive"
        and bool(rm.cols.feasibility)
        and rm.model.n_row >= PER_CUT_MIN_ROWS
    )
