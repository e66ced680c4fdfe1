"""The paper's MILP-static formulation on Gurobi, from the model our own builder made.

FlowTest solves the routing MILP (method.md §5) in two phases on HiGHS (maximum flow,
then fewest cuts at that flow), seeded by a heuristic. The paper solved one MILP with the
combined objective ``F - (1/|E|) sum_e d_e`` on Gurobi. To compare the two without a
second copy of the MILP builder, :func:`capture_models` records the model that
:mod:`synthesis.routing.solve` hands to HiGHS during a synthesis, :func:`combined_model` gives it
the paper's one combined objective (scaled by ``|E|``: ``|E| F - sum_e d_e``, the same
optimum with integral coefficients, so an absolute gap below 1 proves it), and
:func:`write_mps` writes it with ``Highs.writeModel`` for :func:`solve_gurobi` to read
with ``gurobipy.read``. :func:`solve_highs_combined` solves the same file on HiGHS in
one phase, which separates the solver's share from the formulation's.

The recorder wraps the ``highspy.Highs`` object that ``synthesis.routing.backends.highs.new_highs`` returns
and reads three calls of the builder: ``passModel`` (the constraints), the last
``changeColsCost`` (phase 2's cut weights: the number of edges of G per cut group)
and phase 2's ``addRow`` (its columns are the flow out of ``Src``). It depends on
those internals; an exported model from ``synthesis.routing.solve`` would replace it.

Gurobi is optional (the ``bench`` extra); nothing here imports it at module level.
"""

from __future__ import annotations

import contextlib
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import highspy
import numpy as np


class _RecordingHighs:
    """Delegates every call to a ``highspy.Highs``; remembers the model and the objectives."""

    def __init__(self, inner: highspy.Highs) -> None:
        self._inner = inner
        self.lp: highspy.HighsLp | None = None
        self.costs: list[np.ndarray] = []
        self.rows: list[np.ndarray] = []

    def passModel(self, lp: highspy.HighsLp) -> Any:  # noqa: N802 (highspy's name)
        self.lp = lp
        return self._inner.passModel(lp)

    def changeColsCost(self, n: int, idx: Any, cost: Any) -> Any:  # noqa: N802
        self.costs.append(np.array(cost, dtype=float, copy=True))
        return self._inner.changeColsCost(n, idx, cost)

    def addRow(self, lo: float, hi: float, n: int, idx: Any, vals: Any) -> Any:  # noqa: N802
        self.rows.append(np.array(idx, dtype=np.int64, copy=True))
        return self._inner.addRow(lo, hi, n, idx, vals)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inner, name)


@dataclass
class CapturedModel:
    """One routing model as our builder made it: constraints, flow columns, cut weights."""

    lp: highspy.HighsLp
    flow_cols: np.ndarray
    cut_cost: np.ndarray


@dataclass
class Capture:
    """The models of every routing solve of one synthesis (one per feasibility round)."""

    recorders: list[_RecordingHighs] = field(default_factory=list)

    def models(self) -> list[CapturedModel]:
        """The complete models (a solve that stopped before phase 2 is left out)."""
        out = []
        for r in self.recorders:
            if r.lp is None or not r.rows or not r.costs:
                continue
            out.append(CapturedModel(r.lp, r.rows[-1], r.costs[-1]))
        return out


@contextlib.contextmanager
def capture_models() -> Iterator[Capture]:
    """Record the routing models :mod:`synthesis.routing.solve` builds inside the ``with`` block."""
    from synthesis.routing.backends import highs

    original = highs.new_highs
    cap = Capture()

    def recording(options: Any) -> Any:
        rec = _RecordingHighs(original(options))
        cap.recorders.append(rec)
        return rec

    highs.new_highs = recording
    try:
        yield cap
    finally:
        highs.new_highs = original


def combined_model(model: CapturedModel, n_edges: int) -> highspy.HighsLp:
    """The model with the paper's one objective, scaled by ``|E|`` and as a minimisation.

    ``maximize F - (1/|E|) sum d`` becomes ``minimize sum_g w_g d_g - |E| F`` (``w_g`` the
    number of G edges of cut group ``g``): the same optimum, integral coefficients.
    """
    lp = model.lp
    cost = np.asarray(model.cut_cost, dtype=float).copy()
    cost[model.flow_cols] -= float(n_edges)
    lp.col_cost_ = cost
    lp.sense_ = highspy.ObjSense.kMinimize
    lp.offset_ = 0.0
    return lp


def write_mps(lp: highspy.HighsLp, path: Path) -> None:
    """Write a model as an MPS file with HiGHS (``Highs.writeModel``)."""
    h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    h.passModel(lp)
    status = h.writeModel(str(path))  # kWarning: HiGHS named the unnamed columns and rows
    if status == highspy.HighsStatus.kError or not path.exists():
        raise RuntimeError(f"HiGHS could not write {path}")


@dataclass
class SolverAnswer:
    """A solve of the combined model: outcome, flow, cut count (edges of G) and time."""

    solver: str
    outcome: str  # optimal | feasible | timeout | size-limit | error
    flow: int | None
    n_cuts: int | None
    seconds: float
    message: str = ""


def _answer_of(x: np.ndarray, model: CapturedModel) -> tuple[int, int]:
    flow = int(round(float(x[model.flow_cols].sum())))
    n_cuts = int(round(float(np.dot(model.cut_cost, np.round(x)))))
    return flow, n_cuts


def solve_gurobi(mps: Path, model: CapturedModel, time_limit: float | None, threads: int | None) -> SolverAnswer:
    """Solve the MPS file with Gurobi; a model over the license's size limit is reported as such."""
    import gurobipy as gp

    try:
        with gp.Env(empty=True) as env:
            env.setParam("OutputFlag", 0)
            env.start()
            m = gp.read(str(mps), env)
            try:
                m.Params.MIPGap = 0.0
                m.Params.MIPGapAbs = 1.0 - 1e-6  # integral objective: a gap below 1 proves it
                if time_limit is not None:
                    m.Params.TimeLimit = float(time_limit)
                if threads is not None:
                    m.Params.Threads = int(threads)
                m.optimize()
                seconds = float(m.Runtime)
                if m.SolCount == 0:
                    outcome = "timeout" if m.Status == gp.GRB.TIME_LIMIT else f"status-{m.Status}"
                    return SolverAnswer("gurobi", outcome, None, None, seconds)
                x = np.array(m.getAttr("X", m.getVars()), dtype=float)
                flow, n_cuts = _answer_of(x, model)
                outcome = "optimal" if m.Status == gp.GRB.OPTIMAL else "feasible"
                return SolverAnswer("gurobi", outcome, flow, n_cuts, seconds)
            finally:
                m.dispose()
    except gp.GurobiError as exc:
        if getattr(exc, "errno", None) == 10010:  # model too large for the size-limited license
            return SolverAnswer("gurobi", "size-limit", None, None, 0.0, str(exc))
        return SolverAnswer("gurobi", "error", None, None, 0.0, str(exc))


def solve_highs_combined(mps: Path, model: CapturedModel, time_limit: float | None, threads: int | None) -> SolverAnswer:
    """Solve the same MPS file on HiGHS in one phase (no heuristic, no two-phase split)."""
    h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    if threads is not None:
        highspy.Highs.resetGlobalScheduler(True)
        h.setOptionValue("threads", int(threads))
    h.setOptionValue("mip_rel_gap", 0.0)
    h.setOptionValue("mip_abs_gap", 1.0 - 1e-6)
    if time_limit is not None:
        h.setOptionValue("time_limit", float(time_limit))
    h.readModel(str(mps))
    t0 = time.perf_counter()
    h.run()
    seconds = time.perf_counter() - t0
    info = h.getInfo()
    if info.primal_solution_status != highspy.SolutionStatus.kSolutionStatusFeasible:
        return SolverAnswer("highs-combined", "timeout", None, None, seconds)
    x = np.asarray(h.getSolution().col_value, dtype=float)
    flow, n_cuts = _answer_of(x, model)
    optimal = h.getModelStatus() == highspy.HighsModelStatus.kOptimal and abs(info.objective_function_value - info.mip_dual_bound) < 1.0 - 1e-6
    return SolverAnswer("highs-combined", "optimal" if optimal else "feasible", flow, n_cuts, seconds)


def compare_on(model: CapturedModel, n_edges: int, time_limit: float | None, threads: int | None, highs_too: bool = True) -> list[SolverAnswer]:
    """Write the combined model once and solve it on Gurobi (and on HiGHS in one phase)."""
    lp = combined_model(model, n_edges)
    with tempfile.TemporaryDirectory(prefix="flowtest-mps-") as d:
        mps = Path(d) / "routing.mps"
        write_mps(lp, mps)
        answers = [solve_gurobi(mps, model, time_limit, threads)]
        if highs_too and answers[0].outcome != "size-limit":  # no comparison to make: save the time
            answers.append(solve_highs_combined(mps, model, time_limit, threads))
    return answers
