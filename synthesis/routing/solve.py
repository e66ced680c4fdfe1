"""The one front of the routing MILP: :func:`solve_routing`, its lazy loop over the
feasibility flows, and the table of backends it picks a solver from (:data:`SOLVERS`), the way
networkx's ``maximum_flow`` takes a ``flow_func``. Every backend meets one contract
(:class:`~synthesis.routing.backends.contract.Backend`, see :mod:`synthesis.routing`).

Example::

    >>> from synthesis.problems.load import load_problem
    >>> from synthesis.problems.problem import build_graphs
    >>> from synthesis.routing.options import MilpOptions
    >>> _, products = build_graphs(load_problem("small-reactive"))
    >>> result = solve_routing(products, MilpOptions(backend="highs", threads=1))
    >>> (result.status, result.flow, int(result.cut_edges.size))
    ('optimal', 2, 4)
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Any

import numpy as np

from ..graphs.consistency import check_consistency
from ..graphs.products import Products
from .backends import cpsat_phases, highs
from .backends.contract import Backend, Least, LeastQuery, Round
from .backends.rules import auto_backend, per_cut_flow_rows
from .certificates import cut_proof
from .groups import static_moves_of
from .model import RoutingModel, build_model
from .options import MilpOptions, check_options
from .phases import flow_of_phase1, routing_result
from .result import RoutingResult, blocked_by, blocked_of_edges, required_entries
from .solver_control import Clock
from .traps import trapped_configurations, trapped_entries

SOLVERS: dict[str, Backend[Any]] = {"highs": highs.BACKEND, "cpsat": cpsat_phases.BACKEND}
"""The backends of the routing model by name (``MilpOptions.backend``): the one table
:func:`solve_routing` picks a solver from. Each entry is a
:class:`~synthesis.routing.backends.contract.Backend`: the same phases, the same answer. Its
names, with ``"auto"`` first, are :data:`synthesis.routing.options.BACKENDS` (the names an option
may take; ``"auto"``: :func:`auto_backend` picks one on the built model)."""


EAGER_FLOW_LIMIT = 200_000  # histories x G_sys edges up to which all feasibility flows go in at once


def solve_routing(products: Products, options: MilpOptions | None = None) -> RoutingResult:
    """Solve the routing MILP for least-restrictive cuts (docs/method.md §5, §7).

    MILP-static has no feasibility flows (c6-c8), as docs/method.md §5 says: static walls
    are part of the map the system sees from its first step, so a correct system
    plans around them, and the test is feasible iff a successful run exists under
    them (``F >= 1``). An entry node that the walls alone doom is one no correct
    system enters (the environments call a run there violated: the system's fault).
    The other variants add the flows where they bind: all of them at once unless
    that would swamp the model (``EAGER_FLOW_LIMIT``), else lazily: the answer is
    checked by graph search, and the flows of the histories whose entry nodes it
    traps are added, until no entry node is trapped. A relaxation's optimum that
    satisfies every omitted constraint is optimal for the full model, so the answer
    is the optimum of docs/method.md §5, reached with the flows only where they bind.

    Beyond the method (with ``options.closed_loop``: c13), closed-loop configurations that
    the restrictions trap although they are not entry nodes are added as entry nodes
    of their history, so no test returned traps the system anywhere. This matters
    with one-way moves (outside docs/method.md §2's bidirectional assumption), where the
    method's optimum can lead the system into a dead end; it is off by default
    because on irreversible systems such as fuel grids it also forbids configurations
    that only a wasteful system reaches, and can make a routable test unroutable.

    Raises
    ------
    InconsistentProblem
        ``unreachable`` or ``unroutable`` (including a MILP without solution, or
        maximum flow 0: every routing cut set would trap the system).

    Examples
    --------
    The routing step alone, on the product graphs of a problem (:func:`synthesis.synthesize`
    runs it, then builds and checks the test):

    >>> from synthesis import load_problem
    >>> from synthesis.problems.problem import build_graphs
    >>> from synthesis.routing.options import MilpOptions
    >>> from synthesis.routing.solve import solve_routing
    >>> _, products = build_graphs(load_problem("small-reactive"))
    >>> result = solve_routing(products, MilpOptions(backend="highs", threads=1))
    >>> result.status, result.flow, int(result.cut_edges.size)
    ('optimal', 2, 4)
    """
    options = options or MilpOptions()
    check_backend(options)
    # small reactive models start with every history's flows (adding them lazily costs
    # more rounds than it saves there); reactive ones whose flows would swamp the model
    # start without
    required = required_entries(products, options)
    eager = options.feasibility == "eager" or (options.feasibility == "auto" and len(required) * products.system.src.size <= EAGER_FLOW_LIMIT)
    entries: dict[int, np.ndarray] = dict(required) if eager else {}
    clock = Clock(options.time_limit, options.after_first)
    rounds = 0
    while True:
        rounds += 1
        try:
            result = _solve_once(products, options, entries, required, clock)
        except FlowsBind as more:
            # the phase-1 answer already traps: add those flows before phase 2
            trapped = more.trapped
        else:
            blocked = blocked_by(products, result)
            trapped = trapped_entries(products, blocked, _with_extra(required, entries))
        if not trapped:
            traps = trapped_configurations(products, blocked) if options.closed_loop else np.zeros(0, dtype=np.int64)
            if traps.size == 0:
                return _with_rounds(result, rounds, entries)
            trapped = {}
            for q in np.unique(products.virtual.hist[traps]):
                trapped[int(q)] = products.projection[traps[products.virtual.hist[traps] == q]]
        grew = False
        for q, nodes in trapped.items():
            base = entries.get(q, required.get(q, np.zeros(0, dtype=np.int64)))
            merged = np.union1d(base, nodes)
            grew |= q not in entries or merged.size > entries[q].size
            entries[q] = merged
        if not grew:
            # the model already holds these flows: the answer cannot change, and the
            # independent checks will report the disagreement as a FlowTest bug
            return _with_rounds(result, rounds, entries)
        if options.progress:
            options.progress(f"routing MILP: adding feasibility flows for {len(trapped)} trapped histories")


def check_backend(options: MilpOptions) -> None:
    """Refuse options that cannot run (:func:`~synthesis.routing.options.check_options`) and a
    backend whose package is missing; ``"auto"`` is resolved once the model is built
    (:func:`auto_backend` decides on its size).

    Raises
    ------
    ProblemError
        (a :class:`ValueError`) For any bad option value (an unknown backend name among them),
        and for ``"cpsat"`` without OR-Tools installed
        (:data:`synthesis.routing.backends.cpsat.MISSING`).
    """
    check_options(options)
    if options.backend in SOLVERS:
        SOLVERS[options.backend].require()


def backend_version(backend: str) -> str:
    """The version of the package a backend's answers depend on (highspy, OR-Tools; highspy's
    for a name outside :data:`SOLVERS`, such as ``"auto"``)."""
    return SOLVERS.get(backend, SOLVERS["highs"]).version()


def solve_least(backend: str, query: LeastQuery) -> Least:
    """Answer ``query`` (:class:`~synthesis.routing.backends.contract.LeastQuery`: the least cost
    over the routing model's solutions with flow >= 1) on ``backend`` where it provides the
    contract's ``least``, else on the first entry of :data:`SOLVERS` that does (HiGHS; also for
    ``"auto"``, which names no backend), so the answer is the same whichever backend the solve
    itself used.

    Example::

        least = solve_least(options.backend, LeastQuery(rm, cost, integral, options, deadline, "the fewest walls"))
        least.status, least.value  # ("optimal", 4.0)
    """
    for candidate in (SOLVERS.get(backend), *SOLVERS.values()):
        if candidate is not None and candidate.least is not None:
            return candidate.least(query)
    raise RuntimeError("no backend of SOLVERS answers a LeastQuery")


def _with_rounds(result: RoutingResult, rounds: int, entries: dict[int, np.ndarray]) -> RoutingResult:
    """``result`` with the feasibility rounds and histories of its solve in its stats."""
    return replace(result, stats={**result.stats, "feasibility_rounds": rounds, "feasibility_histories": len(entries)})


def _with_extra(kept: dict[int, np.ndarray], extra: dict[int, np.ndarray]) -> dict[int, np.ndarray]:
    out = dict(kept)
    for q, nodes in extra.items():
        out[q] = np.union1d(out.get(q, np.zeros(0, dtype=np.int64)), nodes)
    return out


class FlowsBind(Exception):
    """Phase 1's answer traps entry nodes whose feasibility flows the model lacks."""

    def __init__(self, trapped: dict[int, np.ndarray]) -> None:
        super().__init__(f"{len(trapped)} histories trapped")
        self.trapped = trapped


def _solve_once(
    products: Products,
    options: MilpOptions,
    entries: dict[int, np.ndarray],
    required: dict[int, np.ndarray],
    clock: Clock,
) -> RoutingResult:
    """One solve of the routing MILP with feasibility flows for the given entry nodes:
    build the model, pick the backend (:data:`SOLVERS`; ``"auto"``: :func:`auto_backend`),
    then its phase 1 (maximum flow) and phase 2 (fewest cuts at that flow, with the walls'
    cut bound of :func:`~synthesis.routing.certificates.cut_proof`).

    Raises :class:`FlowsBind` when the maximum-flow answer already traps ``required``
    entry nodes outside ``entries`` (before the costlier fewest-cuts phase)."""
    note = options.progress or (lambda msg: None)
    t0 = time.perf_counter()
    rm = build_model(products, options, entries, check_consistency(products))
    graph_seconds = time.perf_counter() - t0
    by_auto = options.backend == "auto"
    if by_auto:
        options = replace(options, backend=auto_backend(rm, options))
    if options.flow_rows == "auto" and per_cut_flow_rows(rm, options):
        options = replace(options, flow_rows="cut")
        rm = build_model(products, options, entries, check_consistency(products))
    backend = SOLVERS[options.backend]
    r = Round(products, rm, options, entries, clock, by_auto)
    missing = {q: v for q, v in required.items() if q not in entries}
    t_solve = time.perf_counter()
    with backend.session(r) as session:
        note(f"{backend.label}, phase 1 of 2: maximum flow")
        first = backend.phase1(session, r)
        flow = flow_of_phase1(rm, first)
        raise_if_flows_bind(rm, products, options, first.x, missing)
        if first.abandoned:  # the time is spent and the solver still holds the model: phase 1's answer stands
            second = first
        else:
            note(f"{backend.label}, phase 2 of 2: fewest cuts at flow {flow}")
            second = backend.phase2(session, r, first.x, flow, cut_proof(products, rm, options, entries, flow))
        figures = backend.figures(session)
    result = routing_result(rm, products, options, first, second, flow, graph_seconds, time.perf_counter() - t_solve, backend.version())
    return replace(result, stats={**result.stats, **figures}) if figures else result


def raise_if_flows_bind(rm: RoutingModel, products: Products, options: MilpOptions, x: np.ndarray, missing: dict[int, np.ndarray]) -> None:
    """Raise :class:`FlowsBind` if phase 1's cuts trap entry nodes of ``missing`` (histories
    whose feasibility flows the model lacks)."""
    if not missing:
        return
    groups = rm.groups
    cut1 = rm.cut_of(x)
    blocked1 = blocked_of_edges(products, np.flatnonzero(cut1[groups.of_edge]))
    blocked1 |= (np.isin(groups.move_key, groups.keys[cut1 & groups.static]) & static_moves_of(products, options))[None, :]
    trapped1 = trapped_entries(products, blocked1, missing)
    if trapped1:
        raise FlowsBind(trapped1)
