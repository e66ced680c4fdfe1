"""Resource limits: problems far beyond what can be solved are refused before any work.

The routing MILP has a binary variable per edge of the product graph G = T x B_pi, and
building G alone holds several arrays per edge, so a large enough grid exhausts memory before
any solver runs. :func:`estimate_size` bounds G from the problem alone, cheaply (no automaton
product is built): at most ``n_moves`` edges per history, and at most the product of the
sub-task automata's sizes as histories. :func:`check_size` refuses a problem whose bound
exceeds the limit, with the estimate and the way to go on (``--no-size-limit`` on the
command line, ``SynthesisOptions(max_graph_edges=None)`` from Python).
"""

from __future__ import annotations

import os
import stat
import time
from dataclasses import dataclass
from pathlib import Path

from ..graphs.automata import specification_product
from ..model.errors import ProblemError, ProblemTooLarge
from ..model.specs import Task
from .problem import Problem

MAX_GRAPH_EDGES = 500_000
"""Default bound on the edges of G (about 6 GB while solving, by :data:`BYTES_PER_EDGE`).
The largest paper instance (mars-exploration) has 7 759 edges; the bounds of the paper's
20x20 random grids (|AP| up to 7) stay below 400 000."""

BYTES_PER_EDGE = 12_000
"""Peak memory per edge of G during synthesis (graphs, MILP model, HiGHS), measured on empty
60x60 and 120x120 grids (docs/benchmarks.md); used for the estimate in messages only."""


@dataclass(frozen=True)
class SizeEstimate:
    """Upper bounds on the sizes synthesis would build."""

    states: int
    moves: int
    histories: int
    edges: int

    @property
    def memory_bytes(self) -> int:
        return self.edges * BYTES_PER_EDGE

    def describe(self) -> str:
        gb = self.memory_bytes / 1e9
        return (
            f"T has {self.states} states and {self.moves} moves; up to {self.histories} histories, so up to "
            f"{self.edges} product-graph edges (up to about {gb:.1f} GB while solving)"
        )


def _task_states(task: Task) -> int:
    """States of a sub-task's automaton (synthesis.graphs.automata.task_automaton)."""
    return len(task.props) + 1 if task.is_visit else 2


def estimate_size(problem: Problem) -> SizeEstimate:
    """Bounds on the product graph of ``problem`` (no automaton product is built)."""
    ts = problem.system
    histories = 1
    for objective in (problem.system_objective, problem.test_objective):
        for task in objective.tasks:
            histories *= _task_states(task)
    return SizeEstimate(int(ts.n_states), int(ts.n_moves), histories, int(ts.n_moves) * histories)


INTERMEDIATE_FACTOR = 64
"""How much larger than the final B_pi an objective's unminimised product may grow while
the exact history count is computed (minimisation shrinks it)."""

MAX_EXPLORED_STATES = 20_000
"""At most this many automaton states are explored to count the histories exactly (about
two seconds); beyond it the problem is refused on the estimate rather than explored for
minutes. The paper's problems need a few hundred at most."""

EXPLORED_STATES_PER_SECOND = 10_000
"""About how many automaton states the exact count explores per second: with a deadline,
the exploration is cut to what the time left allows."""


def check_size(problem: Problem, max_edges: int | None, deadline: float | None = None) -> SizeEstimate | None:
    """Refuse ``problem`` if its product graph may exceed ``max_edges`` (``None``: no limit).

    The cheap bound decides when it is small enough; otherwise the histories are counted
    exactly, with the automaton products explored only up to what the limit allows, at
    most :data:`MAX_EXPLORED_STATES` states, and (with ``deadline``, a
    :func:`time.perf_counter` time) no more than the time left allows: beyond that the
    problem is refused on the estimate.

    Raises
    ------
    ProblemTooLarge
        With the estimate and the way to go on anyway.
    TimeoutError
        If ``deadline`` has passed before the count could start.
    """
    if max_edges is None:
        return None
    est = estimate_size(problem)
    if est.edges <= max_edges:
        return est
    way = "pass --no-size-limit (SynthesisOptions(max_graph_edges=None)) to try anyway"
    if est.moves > max_edges:
        raise ProblemTooLarge(
            f"problem {problem.name!r} is too large to synthesize: T alone has {est.moves} moves, so its product "
            f"graph has more than the limit of {max_edges} edges (more than about {est.moves * BYTES_PER_EDGE / 1e9:.1f} GB "
            f"while solving); {way}"
        )
    cap = max(max_edges // max(est.moves, 1), 1)
    budget = min(cap * INTERMEDIATE_FACTOR, MAX_EXPLORED_STATES)
    if deadline is not None:
        left = deadline - time.perf_counter()
        if left <= 0:
            raise TimeoutError("the time limit passed before the problem's size was checked")
        budget = min(budget, max(int(left * EXPLORED_STATES_PER_SECOND / 2), 1))
    try:
        spec = specification_product(problem.system_objective, problem.test_objective, problem.system.letters(), max_states=budget)
    except ProblemTooLarge:
        spec = None
    if spec is None or spec.dba.n_states > cap:
        raise ProblemTooLarge(
            f"problem {problem.name!r} is too large to synthesize: T has {est.states} states and {est.moves} moves "
            f"and its objectives up to {est.histories} histories (more than {cap} found, or more than the {budget} "
            f"automaton states explored to count them), so more than {max_edges} product-graph edges "
            f"(more than about {max_edges * BYTES_PER_EDGE / 1e9:.1f} GB while solving); {way}"
        )
    est = SizeEstimate(est.states, est.moves, spec.dba.n_states, est.moves * spec.dba.n_states)
    if est.edges > max_edges:
        raise ProblemTooLarge(f"problem {problem.name!r} is too large to synthesize: {est.describe()}, above the limit of {max_edges} edges; {way}")
    return est


def check_file_size(path: str | Path, what: str, limit: int) -> None:
    """Refuse a regular file larger than ``limit`` bytes by its size alone, before a byte
    of it is read (``stat``): a 3 GB file costs nothing. A missing file, a folder or a
    special file is left to the reader, which refuses it with its own message.

    Raises
    ------
    ProblemError
        Naming the file, its size and the limit.
    """
    try:
        st = os.stat(path)
    except OSError:
        return
    if stat.S_ISREG(st.st_mode) and st.st_size > limit:
        raise ProblemError(f"{what} {str(path)!r} is {st.st_size / 2**20:.0f} MiB, larger than {limit // 2**20} MiB: refused before reading it")
