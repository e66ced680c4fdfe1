"""From a problem to a checked test: automata, products, routing MILP, strategy, checks.

:func:`synthesize` is the one entry point for every kind of problem; agent problems go
through :func:`synthesize_agent_test`, which runs the counterexample-guided loop of
:mod:`synthesis.test_agent.loop` on the same graphs and MILP options. What they return, a
:class:`~synthesis.synthesized_test.SynthesizedTest`, is defined in
:mod:`synthesis.synthesized_test` (and importable from here too), so that reading a test needs
none of the solvers this module imports; its options, :class:`~synthesis.options.SynthesisOptions`,
likewise live in :mod:`synthesis.options`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace

from .checks.physical import cap_count, physical_counts
from .checks.verify import check_test, restricted_edges, routed_flow
from .graphs.automata import SpecificationProduct
from .graphs.products import Products
from .model.agent_system import TestAgent
from .model.errors import CheckFailed, InconsistentProblem, ProblemError
from .model.strategy import TestStrategy
from .options import SYNTHESIS_RULES as SYNTHESIS_RULES  # re-exported: the options live in synthesis.options
from .options import SynthesisOptions as SynthesisOptions  # re-exported, as SYNTHESIS_RULES
from .problems.diagnose import check_problem_consistency
from .problems.limits import check_size
from .problems.problem import Problem, build_graphs, check_caps
from .routing.backends import cpsat
from .routing.backends.rules import AUTO_CPSAT_MODES
from .routing.caps.fewest import FOUND_SECONDS, FOUND_SHARE, Fewest, fewest_within, found_with
from .routing.caps.messages import CAP_NOUNS, CapsTimeout, caps_text
from .routing.caps.refusal import check_caps_reachable
from .routing.options import Budgets, MilpOptions, RunOptions, values_of
from .routing.options import check_options as check_routing_options
from .routing.restrictions import strategy_from_routing
from .routing.solve import solve_routing
from .synthesized_test import SynthesizedTest as SynthesizedTest  # re-exported: the result lives in synthesis.synthesized_test
from .test_agent.loop import counterexample_loop


def check_options(options: SynthesisOptions) -> None:
    """Refuse bad options before any work: every field by its rule
    (:func:`synthesis.routing.options.check_options` with :data:`SYNTHESIS_RULES`), and the
    ``cpsat`` backend without OR-Tools installed.

    Raises
    ------
    ProblemError
        Naming the option (``option time_limit must be a positive finite number of seconds, not -1``).
    """
    check_routing_options(options, SYNTHESIS_RULES)
    if options.backend == "cpsat":
        cpsat.require()


def caps_of(problem: Problem, options: SynthesisOptions) -> dict[str, int]:
    """The caps a synthesis honours: the problem's, each replaced by the option's."""
    caps = dict(problem.caps)
    caps.update(check_caps(options.caps or {}, " (option caps)"))
    return caps


def routing_mode(problem: Problem) -> str:
    """The routing model's mode for ``problem`` (``MilpOptions.mode``)."""
    return "mixed" if problem.kind in ("mixed", "agent") else problem.kind


def may_use_cpsat(problem: Problem, backend: str) -> bool:
    """Whether synthesizing ``problem`` on ``backend`` may solve on CP-SAT: ``"cpsat"``, or
    ``"auto"`` on a static or reactive problem (:data:`~synthesis.routing.backends.rules.AUTO_CPSAT_MODES`;
    the model's size decides later) with OR-Tools installed. Known before any graph is built,
    so a CP-SAT child started early can be ended at once when it will not be used."""
    return backend == "cpsat" or (backend == "auto" and routing_mode(problem) in AUTO_CPSAT_MODES and cpsat.available())


def milp_options(problem: Problem, options: SynthesisOptions) -> MilpOptions:
    """The routing MILP options a problem asks for: the model from the problem (its mode,
    static area, cut rules, caps with the options' in their place), and the options' budgets
    and run options as they are, ``time_limit`` and ``threads`` with their fallbacks (the
    problem's time limit, one thread)."""
    budgets = values_of(options, Budgets)
    budgets["time_limit"] = time_limit_of(problem, options)
    budgets["threads"] = options.threads if options.threads is not None else 1
    return MilpOptions(
        mode=routing_mode(problem),
        static_moves=problem.static_moves,
        bidirectional=problem.bidirectional_cuts,
        tie_places=problem.tie_places,
        block_states=problem.kind == "agent",
        closed_loop=options.closed_loop,
        caps=caps_of(problem, options),
        one_way_walls=problem.one_way_walls,
        **budgets,
        **values_of(options, RunOptions),
    )


CHECK_SECONDS_PER_EDGE = 1e-4
"""Seconds per edge of G kept back from the solver's time limit for what follows its last
run: the answer read back and checked against the model, the strategy, the independent
checks, the summary, and the solver's late look at its clock. Sized from the 500-state graph of
19,000 edges of ``tests/synthesis/test_limits.py``, with room for a loaded machine (the figures
are in docs/history.md)."""

RESERVE_SHARE = 0.2
"""At most this share of the time limit is kept back for what follows the solve."""


def time_limit_of(problem: Problem, options: SynthesisOptions) -> float | None:
    """The time limit a synthesis honours: the option's, else the problem's (``None``: none)."""
    return options.time_limit if options.time_limit is not None else problem.time_limit


def remaining_time(problem: Problem, options: SynthesisOptions, spent: float, edges: int = 0) -> SynthesisOptions:
    """``options`` with the time limit that is left for the solve after ``spent`` seconds
    (the size check, graph building, the consistency check), less a reserve for what
    follows the solve on a product graph of ``edges`` edges (:data:`CHECK_SECONDS_PER_EDGE`,
    at most :data:`RESERVE_SHARE` of the limit): the limit bounds the whole synthesis, not
    the solve alone.

    Raises
    ------
    TimeoutError
        If the limit is already spent.
    """
    limit = time_limit_of(problem, options)
    if limit is None:
        return options
    reserve = min(RESERVE_SHARE * limit, CHECK_SECONDS_PER_EDGE * edges)
    if spent + reserve >= limit:
        raise TimeoutError(f"building the product graphs took {spent:.1f} s, the whole time limit of {limit:g} s")
    return replace(options, time_limit=limit - spent - reserve)


def graphs_and_milp(
    problem: Problem, options: SynthesisOptions, started: float, note: Callable[[str], None]
) -> tuple[SpecificationProduct, Products, float, MilpOptions]:
    """What every synthesis does before its solve: start CP-SAT's child process when the
    ``cpsat`` backend is asked for (OR-Tools loads in it while the graphs are built), build
    the automata and product graphs and check the problem's consistency on them
    (:func:`~synthesis.problems.diagnose.check_problem_consistency`), and the routing MILP's
    options with the time that is left since ``started`` (:func:`remaining_time`).

    Returns
    -------
    tuple
        The specification product, the product graphs, the seconds they took to build and
        check (``SynthesizedTest.graph_seconds``) and the MILP options.

    Raises
    ------
    InconsistentProblem
        If the goal is unreachable or the test objective cannot be routed.
    TimeoutError
        If building the graphs spent the whole time limit.
    """
    if options.backend == "cpsat":
        cpsat.prestart()
    t0 = time.perf_counter()
    note("building automata and product graphs")
    spec, products = build_graphs(problem)
    check_problem_consistency(problem, products)
    graph_seconds = time.perf_counter() - t0
    milp = milp_options(problem, remaining_time(problem, options, time.perf_counter() - started, int(products.virtual.n_edges)))
    return spec, products, graph_seconds, milp


def synthesize(problem: Problem, options: SynthesisOptions | None = None) -> SynthesizedTest:
    """Synthesize and check the least-restrictive test of a static, reactive or mixed problem.

    Raises
    ------
    InconsistentProblem
        If the goal is unreachable (``"unreachable"``), the test objective cannot be routed
        (``"unroutable"``; within the caps too), or the system objective already implies it
        (``"implied"``); the message names the conjunct or visit to blame.
    CheckFailed
        If the answer fails an independent check (a FlowTest bug).

    Examples
    --------
    >>> from synthesis import load_problem, synthesize
    >>> test = synthesize(load_problem("small-reactive"))
    >>> test.routing.status, test.routing.flow, len(test.routing.cut_edges), test.checks.bypass_flow
    ('optimal', 2, 4, 0)
    """
    options = options or SynthesisOptions()
    started = time.perf_counter()
    check_options(options)
    limit = time_limit_of(problem, options)
    check_size(problem, options.max_graph_edges, deadline=None if limit is None else started + limit)
    if problem.kind == "agent":
        return synthesize_agent_test(problem, options, started=started)
    note = options.progress or (lambda msg: None)
    spec, products, graph_seconds, milp = graphs_and_milp(problem, options, started, note)
    bounds: dict[str, int] = {}
    try:
        if milp.caps:
            note(f"checking {caps_text(milp.caps)} against what every test needs (lower bounds)")
        bounds, milp = caps_checked(products, milp)
        routing = solve_routing(products, milp)
    except InconsistentProblem as exc:
        raise over_caps(products, milp, exc, note, None if limit is None else started + limit) from None
    except TimeoutError as exc:
        raise capped_timeout(milp, exc, bounds, products, None if limit is None else started + limit) from None
    setting = options.setting or problem.extras.get("setting", "instantaneous")
    strategy = strategy_from_routing(products, routing, setting)
    if routing.status != "optimal":
        # a time-limited answer's flow variables need not be a maximum flow of its own
        # cut set; the test's flow is what its restrictions let through
        routing = replace(routing, flow=routed_flow(products, restricted_edges(products, strategy)))
    note("checking the test (bypass flow, feasibility)")
    checks = check_test(products, strategy, routing.flow, closed_loop=options.closed_loop)
    check_caps_held(problem, strategy, milp.caps)
    return SynthesizedTest(problem, spec, products, routing, strategy, checks, graph_seconds, caps=milp.caps)


def check_caps_held(problem: Problem, strategy: TestStrategy, caps: dict[str, int]) -> None:
    """The independent check of the caps: the test's physical restrictions, counted from its
    strategy (:func:`~synthesis.checks.physical.physical_counts`, not from the solver's cut
    groups), within every cap.

    Raises
    ------
    CheckFailed
        If a cap is exceeded (a FlowTest bug: the solver honours the caps).
    """
    if not caps:
        return
    counts = physical_counts(problem.system, strategy)
    for cap, limit in caps.items():
        used = cap_count(counts, cap)
        if used > limit:
            raise CheckFailed(f"the test uses {used} {CAP_NOUNS[cap]}, above its cap {cap} = {limit}")


def caps_checked(products: Products, milp: MilpOptions) -> tuple[dict[str, int], MilpOptions]:
    """:func:`~synthesis.routing.caps.refusal.check_caps_reachable` (refuse a cap no test fits, and
    the lower bounds it proves), and ``milp`` with the time it took taken off its time limit,
    so the limit holds for the check and the solve together.

    Raises
    ------
    InconsistentProblem
        A cap no test fits.
    """
    if not milp.caps:
        return {}, milp
    t0 = time.perf_counter()
    bounds = check_caps_reachable(products, milp)
    if milp.time_limit is None:
        return bounds, milp
    left = milp.time_limit - (time.perf_counter() - t0)  # the check takes at most a share of it
    left -= found_reserve(milp.time_limit)
    return bounds, replace(milp, time_limit=max(left, 0.05))


def found_reserve(time_limit: float | None) -> float:
    """The seconds of a capped synthesis's time limit kept for
    :func:`~synthesis.routing.caps.fewest.found_with` (``FOUND_SECONDS`` without a limit)."""
    return FOUND_SECONDS if time_limit is None else min(FOUND_SECONDS, FOUND_SHARE * time_limit)


def capped_timeout(
    milp: MilpOptions,
    exc: TimeoutError,
    bounds: dict[str, int],
    products: Products | None = None,
    deadline: float | None = None,
) -> TimeoutError:
    """A time limit that ended a capped solve before any test: ``exc`` with what is known of
    the caps (``bounds``: the lower bounds :func:`synthesis.routing.caps.refusal.check_caps_reachable`
    proved before the solve; with ``products``, the items of a test found with each cap
    lifted, :func:`synthesis.routing.caps.fewest.found_with`, by ``deadline``: the synthesis's, a
    ``perf_counter`` time, whose last share :func:`caps_checked` kept for it; ``None``:
    :data:`~synthesis.routing.caps.fewest.FOUND_SECONDS` from now), so the user can tell a cap too tight
    from a time limit too short and sees the band the fewest lies in; a
    :class:`~synthesis.routing.caps.messages.CapsTimeout` whose advice is a higher cap or time limit
    (a gap cannot help: no test was found).

    Example of the message: ``... no test with at most 7 walls was found, nor proven
    impossible: at least 5 walls are needed (proven), at most 7 allowed, and a test with 9
    walls was found (a cap of 9 allows it)``."""
    if not milp.caps:
        return exc
    known = []
    if deadline is None:
        deadline = time.perf_counter() + FOUND_SECONDS
    for cap, limit in milp.caps.items():
        noun = CAP_NOUNS[cap].split(" (")[0]
        said = f"at least {bounds[cap]} {noun} are needed (proven), at most {limit} allowed" if cap in bounds else ""
        found = None if products is None else found_with(products, milp, cap, deadline)
        if found is not None and found > limit:
            said += f"{', and ' if said else ''}a test with {found} {noun} was found (a cap of {found} allows it)"
        if said:
            known.append(said)
    said = f": {'; '.join(known)}" if known else ""
    return CapsTimeout(f"{exc}; no test with {caps_text(milp.caps)} was found, nor proven impossible{said}")


def over_caps(
    products: Products, milp: MilpOptions, exc: InconsistentProblem, note: Callable[[str], None], deadline: float | None = None
) -> InconsistentProblem:
    """The error to raise when the routing solve found no test: ``exc`` itself without caps
    (or when the problem has no test whatever the caps); with caps, a message that names
    them and how many items a test needs (:func:`synthesis.routing.caps.fewest.fewest_within`):
    ``no test with at most 3 doors routes ... : the fewest that does is 5 doors``. That
    solve ends by ``deadline`` (the synthesis's, a ``perf_counter`` time; ``None``: at most
    :data:`~synthesis.routing.caps.fewest.FEWEST_SECONDS`)."""
    if not milp.caps or exc.reason not in ("unroutable", "infeasible") or str(exc).startswith("no test with"):
        return exc
    note("no test within the caps: finding how few restrictions a test needs")
    left = deadline
    uncapped = replace(milp, caps={})
    parts = []
    for cap, limit in milp.caps.items():
        fewest = fewest_within(products, replace(uncapped, caps=milp.caps), cap, deadline=left)
        if fewest.value is None:
            if len(milp.caps) == 1:
                return exc  # no test at all: the caps are not the reason
            parts.append(f"{CAP_NOUNS[cap]}: no test routes it within the other caps")
            continue
        if fewest.value <= limit and not fewest.exact:
            fewest = Fewest(limit + 1, False, fewest.timed_out) if len(milp.caps) == 1 else fewest
        parts.append(fewest.text(CAP_NOUNS[cap]))
    if exc.reason == "infeasible":  # a test agent's loop: the caps with the agent's own limits
        return InconsistentProblem(
            "infeasible",
            f"no test with {caps_text(milp.caps)} exists for this test agent: {exc}; routing alone (the agent aside): "
            f"{'; '.join(parts)}; raise the cap or drop it",
        )
    return InconsistentProblem(
        "unroutable",
        f"no test with {caps_text(milp.caps)} routes every successful execution through the test objective "
        f"without trapping the system: {'; '.join(parts)}; raise the cap or drop it",
    )


def synthesize_agent_test(
    problem: Problem,
    options: SynthesisOptions | None = None,
    max_iterations: int | None = None,
    prefilter: bool = True,
    reasons: bool = True,
    started: float | None = None,
) -> SynthesizedTest:
    """Synthesize a test agent strategy for an agent problem (docs/method.md §7).

    Builds the graphs and the problem's MILP options and runs
    :func:`synthesis.test_agent.loop.counterexample_loop` on them.

    Parameters
    ----------
    problem
        A problem of kind ``"agent"`` with ``problem.agent`` a :class:`TestAgent`.
    options
        Time limit, gap, threads, progress, setting, closed-loop checks.
    max_iterations
        Bound on MILP solves; default: ``options.agent_iterations`` if set, else the
        agent's ``max_iterations`` (100 unless the problem says otherwise).
    prefilter
        Exclude, before the first solve, the cuts no agent can hold (see
        :func:`~synthesis.test_agent.loop.counterexample_loop`).
    reasons
        Exclude with each rejected cut set every cut set rejected for the same reason
        (see :func:`~synthesis.test_agent.loop.counterexample_loop`); ``False`` excludes the cut
        set alone (the loop of docs/method.md §7 as written; same answer, more solves).
    started
        ``perf_counter`` time the synthesis began (default: now): the time limit runs from it.

    Returns
    -------
    SynthesizedTest
        With ``agent`` an :class:`~synthesis.test_agent.loop.AgentSynthesis`.

    Raises
    ------
    ProblemError
        If the problem has no test agent or no static area.
    InconsistentProblem
        ``unreachable``/``unroutable`` when the first MILP says so; ``infeasible`` when no
        cut set remains after counterexamples, or the iteration bound is reached.
    CheckFailed
        If the result fails an independent check (a FlowTest bug).
    """
    options = options or SynthesisOptions()
    started = time.perf_counter() if started is None else started
    limit = time_limit_of(problem, options)
    agent = problem.agent
    if not isinstance(agent, TestAgent):
        raise ProblemError(f"problem {problem.name!r} is an agent problem without a test agent; add [environment.agent]")
    if problem.static_moves is None:
        raise ProblemError(f"agent problem {problem.name!r} has no static area (static_moves)")
    bound = max_iterations or options.agent_iterations or agent.max_iterations
    note = options.progress or (lambda msg: None)
    spec, products, graph_seconds, milp = graphs_and_milp(problem, options, started, note)
    try:
        _, milp = caps_checked(products, milp)
        outcome = counterexample_loop(
            products,
            agent,
            milp,
            problem.static_moves,
            setting=options.setting or problem.extras.get("setting", "instantaneous"),
            bound=bound,
            prefilter=prefilter,
            reasons=reasons,
            closed_loop=options.closed_loop,
            note=note,
            graph_seconds=graph_seconds,
        )
    except InconsistentProblem as exc:
        raise over_caps(products, milp, exc, note, None if limit is None else started + limit) from None
    check_caps_held(problem, outcome.strategy, milp.caps)
    timings = outcome.solution.timings
    return SynthesizedTest(
        problem,
        spec,
        products,
        outcome.routing,
        outcome.strategy,
        outcome.checks,
        graph_seconds,
        agent=outcome.solution,
        extra_stats={"agent_seconds": dict(timings)},
        caps=milp.caps,
    )
