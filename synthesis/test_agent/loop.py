"""The counterexample-guided loop of docs/method.md §7: from a routing cut set to a test agent
strategy, or a proof that none exists.

:func:`counterexample_loop` solves MILP-agent (the routing MILP of
:mod:`synthesis.routing.solve` in mode ``"mixed"`` with the problem's static area, the
blocked-state penalties ``block_states`` and the exclusion rows of rejected cut sets),
builds the test-agent game of :mod:`synthesis.test_agent.game` for each cut set and solves it
with :mod:`synthesis.test_agent.gr1`; a cut set the agent cannot realize is excluded
(``sum_{e in C} d_e <= |C| - 1``) and the MILP solved again. The winning strategy is
tabulated (:mod:`synthesis.test_agent.controller`) and checked in closed loop
(:mod:`synthesis.test_agent.closed_loop`), by the GR(1) strategy check and by the routing checks
of :mod:`synthesis.checks.verify`. :func:`synthesis.pipeline.synthesize_agent_test` wraps it
into a :class:`~synthesis.pipeline.SynthesizedTest`.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..checks.verify import CheckReport, check_test
from ..graphs.products import Products
from ..model.agent_system import TestAgent, place_json
from ..model.errors import CheckFailed, InconsistentProblem
from ..model.strategy import TestStrategy
from ..model.systems import TransitionSystem
from ..routing.groups import cut_groups
from ..routing.options import Exclusion, MilpOptions
from ..routing.restrictions import strategy_from_routing
from ..routing.result import RoutingResult
from ..routing.solve import solve_routing
from .game import build_agent_game, realizability_exclusions, trapped_nodes
from .gr1.solver import solve as solve_gr1
from .realize import AgentSynthesis as AgentSynthesis  # re-exported: the agent's result lives in realize
from .realize import checked_controller as checked_controller
from .realize import realize_agent_strategy as realize_agent_strategy
from .reasons import Reason, trap_reason, unrealizable_reason

# ------------------------------------------------------ the counterexample-guided loop


def _restrictable_for_agent(ts: TransitionSystem, agent: TestAgent, static: np.ndarray) -> np.ndarray:
    """The harness for MILP-agent: a reactive move into a place the agent can never
    occupy at a turn of the system cannot be restricted (g6 would need the agent there),
    so it is fixed uncut. This only prunes cut sets the game would reject; static moves
    keep their harness."""
    reach = agent.occupiable_states() & (agent.place_of_state >= 0)
    reach_place = np.zeros(len(ts.places), dtype=bool)
    reach_place[agent.place_of_state[reach]] = True
    out: np.ndarray = ts.restrictable & (static | reach_place[ts.place[ts.dst]])
    return out


def _rejected_text(iterations: list[dict[str, Any]], shown: int = 4) -> str:
    """Which restrictions the test agent could not realize: the places each rejected cut
    set needed it to block, and why (it could not be there in time, or the cuts trap the
    system), the last ``shown`` of them."""
    parts = []
    for rec in iterations[-shown:]:
        places = ", ".join(json.dumps(p, separators=(",", ":")) for p in rec["blocked_places"]) or "none"
        why = "the agent cannot reach them in time" if rec.get("verdict") == "unrealizable" else rec.get("verdict", "rejected")
        parts.append(f"cut set {rec['iteration']} blocks places {places}: {why}")
    more = f" (and {len(iterations) - shown} earlier)" if len(iterations) > shown else ""
    return "rejected" + more + ": " + "; ".join(parts)


@dataclass(frozen=True)
class AgentOutcome:
    """What :func:`counterexample_loop` returns: the realizable routing answer, its test
    strategy and checks, and the synthesized agent."""

    routing: RoutingResult
    strategy: TestStrategy
    checks: CheckReport
    solution: AgentSynthesis


def counterexample_loop(
    products: Products,
    agent: TestAgent,
    milp: MilpOptions,
    static_moves: np.ndarray,
    *,
    setting: str,
    bound: int,
    prefilter: bool = True,
    reasons: bool = True,
    closed_loop: bool = False,
    note: Callable[[str], None] | None = None,
    graph_seconds: float = 0.0,
) -> AgentOutcome:
    """Synthesize a test agent strategy on the product graphs of an agent problem (docs/method.md §7).

    The loop: exclude what no agent can realize (a move into a place the agent can
    never occupy at the system's turn is unrestrictable; cuts it could never hold are
    excluded); solve MILP-agent; reject the cut set if it traps the system somewhere
    reachable (:func:`~synthesis.test_agent.game.trapped_nodes`); build the test-agent game
    from ``R(q)`` and ``Obs`` and solve it; if the agent cannot win, exclude the cut set
    with every cut set rejected for the same reason (:mod:`synthesis.test_agent.reasons`; with
    ``reasons=False`` the cut set alone, ``sum_{e in C} d_e <= |C| - 1``) and solve again. The winning strategy is tabulated
    (:class:`~synthesis.test_agent.controller.AgentController`) and checked in closed loop (:func:`~synthesis.test_agent.closed_loop.verify_closed_loop`),
    by :func:`synthesis.test_agent.gr1.verify.verify_strategy` and by the routing checks of
    :mod:`synthesis.checks.verify`.

    Parameters
    ----------
    products
        The product graphs of the problem.
    agent
        The test agent.
    milp
        The routing MILP options of the problem; the loop solves them in mode ``"mixed"``
        over ``static_moves`` with the blocked-state penalties (a new value, ``milp`` is
        not changed).
    static_moves
        The problem's static area (``bool`` over the moves of ``T``).
    setting
        The obstacle setting of the test strategy.
    bound
        Bound on MILP solves.
    prefilter
        Exclude, before the first solve, the cuts no agent can hold
        (:func:`~synthesis.test_agent.game.realizability_exclusions`); this never changes the
        optimum, only which equally good cut set is tried first and how many solves the
        loop needs.
    reasons
        Exclude with each rejected cut set every cut set rejected for the same reason
        (:mod:`synthesis.test_agent.reasons`: a core of cuts and the groups that must stay
        open), not the cut set alone; sound, so the answer keeps its flow and cost, and
        the loop needs fewer solves.
    closed_loop
        Passed to :func:`~synthesis.checks.verify.check_test`.
    note
        Progress messages.
    graph_seconds
        Seconds spent building the graphs (reported in the timings).

    Raises
    ------
    InconsistentProblem
        ``unreachable``/``unroutable`` when the first MILP says so; ``infeasible`` when no
        cut set remains after counterexamples, or the iteration bound is reached.
    CheckFailed
        If the result fails an independent check (a FlowTest bug).
    """
    say: Callable[[str], None] = note or (lambda msg: None)
    t_start = time.perf_counter()
    timings = {"graphs": graph_seconds, "milp": 0.0, "game": 0.0, "gr1": 0.0, "reasons": 0.0, "verify": 0.0, "total": 0.0}
    ts = products.ts
    mopts = replace(milp, mode="mixed", static_moves=static_moves, block_states=True, exclusions=list(milp.exclusions))
    harness = _restrictable_for_agent(ts, agent, static_moves)
    pruned = bool(np.any(ts.restrictable & ~harness))
    milp_products = replace(products, ts=replace(ts, restrictable=harness))
    if prefilter:
        necessary = realizability_exclusions(milp_products, agent, cut_groups(milp_products, mopts))
        mopts = replace(mopts, exclusions=[*mopts.exclusions, *(Exclusion(tuple(k)) for k in necessary)])
        pruned = pruned or bool(necessary)
    groups = cut_groups(milp_products, mopts)
    iterations: list[dict[str, Any]] = []
    for it in range(1, bound + 1):
        t = time.perf_counter()
        try:
            routing = solve_routing(milp_products, mopts)
        except InconsistentProblem as exc:
            if it == 1 and (exc.reason != "unroutable" or not pruned):
                raise
            if it == 1:
                raise InconsistentProblem(
                    "infeasible",
                    f"no test agent strategy exists: no routing cut set restricts only moves into places the test agent can occupy ({exc})",
                ) from None
            raise InconsistentProblem(
                "infeasible",
                f"no test agent strategy exists: after {it - 1} rejected cut set(s) no routing cut set "
                f"remains that the test agent could realize ({exc}); {_rejected_text(iterations)}",
            ) from None
        finally:
            timings["milp"] += time.perf_counter() - t
        strategy = strategy_from_routing(products, routing, setting)
        record: dict[str, Any] = {
            "iteration": it,
            "flow": routing.flow,
            "cuts": int(routing.cut_edges.size),
            "blocked_places": [place_json(ts, int(p)) for p in routing.blocked_places],
            "milp_seconds": time.perf_counter() - t,
        }
        iterations.append(record)
        trapped = trapped_nodes(products, strategy)
        reason: Reason | None = None
        cut_mask = np.isin(groups.keys, np.asarray(routing.cut_group_keys, dtype=np.int64))
        if trapped.size:
            v = int(trapped[0])
            record["verdict"] = f"traps the system at {ts.states[int(products.virtual.state[v])]}"
            if reasons:
                t = time.perf_counter()
                reason = trap_reason(products, groups, cut_mask, strategy, v)
                timings["reasons"] += time.perf_counter() - t
        else:
            t = time.perf_counter()
            game = build_agent_game(products, strategy, agent)
            timings["game"] += time.perf_counter() - t
            t = time.perf_counter()
            result = solve_gr1(game.game)
            record["gr1_seconds"] = time.perf_counter() - t
            timings["gr1"] += record["gr1_seconds"]
            record["positions"] = game.n_positions
            record["verdict"] = "realizable" if result.realizable else "unrealizable"
            if reasons and not result.realizable:
                t = time.perf_counter()
                reason = unrealizable_reason(products, groups, cut_mask, agent)
                timings["reasons"] += time.perf_counter() - t
        say(f"agent loop {it}/{bound}: flow {routing.flow}, {routing.cut_edges.size} cuts, blocked places {record['blocked_places']}: {record['verdict']}")
        if record["verdict"] == "realizable":
            break
        exclusion = Exclusion(tuple(routing.cut_group_keys))
        if reason is not None and reason.exclusion.excludes(set(routing.cut_group_keys)):
            exclusion = reason.exclusion
            record["reason"] = {"cut": len(exclusion.cut), "open": len(exclusion.open), "games": reason.games}
        mopts = replace(mopts, exclusions=[*mopts.exclusions, exclusion])
    else:
        raise InconsistentProblem(
            "infeasible",
            f"no test agent strategy found within the bound of {bound} iterations of the counterexample-guided "
            f"loop ({bound} cut sets rejected; {_rejected_text(iterations)}); raise max_iterations in "
            "[environment.agent] to search further",
        )
    t = time.perf_counter()
    say("checking the agent strategy in closed loop")
    if result.strategy is None:  # a realizable game always has a strategy
        raise CheckFailed("the GR(1) solver reported a realizable game without a strategy")
    controller, report = checked_controller(products, strategy, agent, game, result.strategy)
    checks = check_test(products, strategy, routing.flow, closed_loop=closed_loop)
    timings["verify"] = time.perf_counter() - t
    timings["total"] = graph_seconds + time.perf_counter() - t_start
    solution = AgentSynthesis(
        agent=agent,
        controller=controller,
        system=ts,
        counterexamples=len(iterations) - 1,
        iterations=iterations,
        game_size=game.size(),
        closed_loop=report,
        timings=timings,
    )
    return AgentOutcome(routing, strategy, checks, solution)
