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
elsewhere and in the other modes. Chosen per model kind on the 5x5 random grid study's
instances, comparing proofs and CPU time (docs/benchmarks/solvers.md, "Where each backend wins"; the figures
are in docs/history.md):

* static models of a few hundred to about 13,000 rows (safety to reaction |AP| = 7): CP-SAT
  proves more of them than HiGHS, and faster; mars-exploration (21,515 rows) stays on HiGHS:
  neither proves its fewest cuts, and its shipped artifact is HiGHS's under a node limit.
* reactive models up to about 2,000 rows (safety, reachability |AP| = 2, 3, reaction
  |AP| = 3): CP-SAT proves all of them, HiGHS not all; from about 2,700 rows (reachability
  |AP| = 4, reaction |AP| = 5 and 7) HiGHS proves some and CP-SAT hardly any. The edge lies
  in the unmeasured gap between those sizes.
* below 200 rows (the built-ins small-reactive, example1, beaver-rescue) HiGHS answers before
  a CP-SAT child could have started, sent the model and solved it.

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
feasibility flows' closing rows per cut column (:func:`per_cut_flow_rows`). They paid on the
5x5 random grids' reaction |AP| = 7 reactive models, the smallest of about 37,000 rows
(docs/benchmarks/solvers.md, "MILP-reactive's phase 2"); smaller models were not measured (reaction |AP| = 5:
about 9,000 rows; reachability |AP| = 4: about 2,800), so they keep docs/method.md's rows and
their answers."""


def per_cut_flow_rows(rm: RoutingModel, options: MilpOptions) -> bool:
    """Whether ``"auto"`` writes the feasibility flows' closing rows per cut column
    (:func:`synthesis.routing.model._add_feasibility` proves the answers the same): on
    HiGHS, for MILP-reactive models of at least :data:`PER_CUT_MIN_ROWS` rows built per flow
    edge. A function of the built model and the options only, so the choice is the same on
    every machine."""
    return options.backend == "highs" and options.mode == "reactive" and bool(rm.cols.feasibility) and rm.model.n_row >= PER_CUT_MIN_ROWS
