"""HiGHS 1.16.0 returns a start it was given as "optimal" when presolve proves better (issue 12).

The reproducer (``data/highs_start_presolve.mps`` and ``.json``): the phase-2 model of the
routing MILP (fewest cuts at flow 2: 54 columns, 39 rows, 5 binaries) of
``tests/synthesis/test_optimality.py::test_reactive_small_graphs[38]``, and the start FlowTest handed
HiGHS, a feasible solution with 3 cuts. The optimum is 1 cut (the exhaustive enumeration
of test_optimality agrees). Options: HiGHS's defaults (presolve on).

* highspy 1.15.1: HiGHS returns a 1-cut solution, objective 1, status optimal.
* highspy 1.16.0: HiGHS logs "MIP start solution is feasible: objective value is 3" and
  "... feasible in the reduced space: objective value is 1", reports status optimal,
  objective 1 and dual bound 1, but ``getSolution()`` is the start itself, objective 3:
  the start's image in the presolved model is optimal there, and what comes back is the
  start, not the postsolved optimum. With presolve off, or without the start, it is right.

So a start that is feasible (checked row by row) is not enough; FlowTest's defence
(:func:`synthesis.routing.backends.highs.run`) checks the returned solution against the model and its
objective against HiGHS's report and dual bound, and solves again without the start when
they disagree. ``test_raw_highs_returns_its_proven_solution`` is the reproducer itself: it
is expected to fail on exactly 1.16.0 (strict: should a 1.16 build return the right
solution, it fails and says the workaround can be revisited).
"""

from __future__ import annotations

import json
from importlib.metadata import version
from pathlib import Path

import highspy
import numpy as np
import pytest

from synthesis.routing.backends.highs import ModelView, run, set_solution, violation
from synthesis.routing.options import MilpOptions

DATA = Path(__file__).resolve().parents[1] / "data"
MODEL = DATA / "highs_start_presolve.mps"
START = np.array(json.loads((DATA / "highs_start_presolve.json").read_text())["start"])
OPTIMUM = 1.0  # fewest cuts (the exhaustive optimum of test_reactive_small_graphs[38])
HIGHSPY = version("highspy")


def _highs() -> highspy.Highs:
    h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    assert h.readModel(str(MODEL)) == highspy.HighsStatus.kOk
    return h


def _start(h: highspy.Highs) -> None:
    sol = highspy.HighsSolution()
    sol.col_value = list(START)
    sol.value_valid = True
    h.setSolution(sol)


def test_the_start_is_feasible_and_not_optimal() -> None:
    """The start satisfies every bound, row and integrality of the model, with 3 cuts."""
    model = ModelView.of(_highs())
    assert violation(model, START) <= 1e-9
    assert float(model.cost @ START) == 3.0


@pytest.mark.xfail(
    HIGHSPY == "1.16.0",
    strict=True,
    reason="HiGHS 1.16.0 with a start and presolve returns the start (3 cuts) while it reports objective 1",
)
def test_raw_highs_returns_its_proven_solution() -> None:
    """The reproducer: HiGHS (defaults, presolve on) given the feasible start; the solution
    it returns must have the objective it reports as proven optimal."""
    h = _highs()
    _start(h)
    h.run()
    assert h.getModelStatus() == highspy.HighsModelStatus.kOptimal
    assert h.getInfo().objective_function_value == pytest.approx(OPTIMUM)
    x = np.asarray(h.getSolution().col_value)
    assert float(ModelView.of(h).cost @ x) == pytest.approx(OPTIMUM)


def test_raw_highs_is_right_without_the_start_or_without_presolve() -> None:
    """What isolates the trigger: the same model without the start, or with the start and
    presolve off, gives a 1-cut solution on every version."""
    for with_start, presolve in ((False, "on"), (True, "off")):
        h = _highs()
        h.setOptionValue("presolve", presolve)
        if with_start:
            _start(h)
        h.run()
        x = np.asarray(h.getSolution().col_value)
        assert float(ModelView.of(h).cost @ x) == pytest.approx(OPTIMUM), (with_start, presolve)


def test_flowtest_gets_the_proven_optimum_with_the_start() -> None:
    """FlowTest's run (start offered, presolve on) returns the 1-cut optimum on every
    supported version, and calls it optimal only because the solution it holds is."""
    h = _highs()
    h.setOptionValue("mip_abs_gap", 1.0 - 1e-6)
    assert set_solution(h, START)  # feasible: offered
    status, gap, x = run(h, None, MilpOptions(), phase="reproducer")
    assert x is not None
    assert float(ModelView.of(h).cost @ x) == pytest.approx(OPTIMUM)
    assert (status, gap) == ("optimal", 0.0)
    assert violation(ModelView.of(h), x) <= 1e-6


def test_an_infeasible_start_is_not_offered() -> None:
    """A start that breaks a row is not handed to HiGHS."""
    h = _highs()
    bad = START.copy()
    bad[0] += 0.5  # a flow value off by a half breaks conservation
    assert not set_solution(h, bad)


def test_start_on_a_model_without_rows() -> None:
    """A static model of column bounds alone: HiGHS hands its matrix back row-wise once phase 2
    adds a row, and the start's check must read it so (regression: a ``ValueError`` from SciPy).

    From s0 both moves reach the goal through I (s0 itself): nothing to cut, flow 2.
    """
    from synthesis.model.systems import graph_system
    from synthesis.pipeline import SynthesisOptions, synthesize
    from synthesis.problems.problem import make_problem

    ts = graph_system(
        ["s0", "s1", "s2"],
        [("s0", "s1"), ("s0", "s2")],
        "s0",
        ["s1", "s2"],
        {"s0": {"I1"}, "s1": {"goal"}, "s2": {"goal"}},
    )
    res = synthesize(make_problem("no-rows", ts, "F goal", "F I1", "static"), SynthesisOptions(backend="highs"))
    assert (res.routing.status, res.routing.flow, res.routing.cut_edges.size) == ("optimal", 2, 0)
