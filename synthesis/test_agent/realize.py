"""The test agent's synthesized strategy and how restrictions get it (docs/method.md §7).

:class:`AgentSynthesis` is what the test agent's synthesis returns
(``SynthesizedTest.agent``): the agent, its look-up-table controller and how the
counterexample-guided loop of :mod:`synthesis.test_agent.loop` got there.
:func:`realize_agent_strategy` gives the agent's strategy again for restrictions already known
to be realizable (a stored test's), by the same game, GR(1) solve and checks as the loop's last
cut set (:func:`checked_controller`). Nothing here solves a routing MILP, so a stored agent
test is rebuilt and checked without a solver.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..graphs.products import Products
from ..model.agent_system import TestAgent
from ..model.errors import CheckFailed
from ..model.strategy import TestStrategy
from ..model.systems import TransitionSystem
from .closed_loop import ClosedLoopReport, verify_closed_loop
from .controller import AgentController, controller_from_strategy
from .game import AgentGame, build_agent_game, trapped_nodes
from .gr1.solver import solve as solve_gr1
from .gr1.strategy import GR1Strategy
from .gr1.verify import StrategyError, verify_strategy


@dataclass(frozen=True)
class AgentSynthesis:
    """The synthesized test agent of an agent problem (``SynthesizedTest.agent``).

    Attributes
    ----------
    agent
        The test agent.
    controller
        Its strategy as a look-up table (restricted to the configurations the closed
        loop reaches).
    system
        The system's transition system (to write cells in outputs).
    counterexamples
        Cut sets rejected by the loop (MILP solves minus one).
    iterations
        One record per MILP solve: flow, cuts, blocked places, verdict, seconds.
    game_size
        Positions, choices, moves and configurations of the final game.
    closed_loop
        What the closed-loop verification explored.
    timings
        Seconds: ``graphs``, ``milp`` (every solve), ``game`` (every build),
        ``gr1`` (every solve), ``verify`` (closed loop, GR(1) check, routing checks),
        ``total``.
    """

    agent: TestAgent
    controller: AgentController
    system: TransitionSystem
    counterexamples: int
    iterations: list[dict[str, Any]]
    game_size: dict[str, int]
    closed_loop: ClosedLoopReport
    timings: dict[str, float]

    def summary(self) -> dict[str, Any]:
        """The agent's part of ``flowtest synthesize --json``."""
        return {
            "counterexamples": self.counterexamples,
            "agent_strategy": {
                "agent_states": self.agent.n_states,
                "first": self.agent.first,
                "iterations": len(self.iterations),
                "game": dict(self.game_size),
                "memory": self.controller.n_memory,
                "table_entries": self.controller.n_entries,
                "closed_loop_positions": self.closed_loop.positions,
                "gr1_seconds": self.timings["gr1"],
                "milp_seconds": self.timings["milp"],
                "total_seconds": self.timings["total"],
                "rejected": [{"iteration": r["iteration"], "reason": r["verdict"]} for r in self.iterations if r["verdict"] != "realizable"],
            },
        }

    def to_dict(self) -> dict[str, Any]:
        """``artifact["agent"]``: the controller plus the agent's cells and parks for drawing."""
        return {
            "controller": self.controller.to_dict(),
            **self.agent.to_dict(self.system),
            "counterexamples": self.counterexamples,
        }


def realize_agent_strategy(products: Products, strategy: TestStrategy, agent: TestAgent) -> tuple[AgentGame, AgentController, ClosedLoopReport]:
    """The test agent's strategy for a routing strategy already known to be realizable
    (a stored test's restrictions): the test-agent game solved again, its GR(1) strategy
    checked (:func:`synthesis.test_agent.gr1.verify.verify_strategy`), tabulated and checked in closed loop,
    exactly as :func:`counterexample_loop` does for its last cut set. Deterministic:
    the same restrictions give the same table.

    Raises
    ------
    CheckFailed
        If the restrictions trap the system, the agent cannot realize them, or the
        strategy fails a check.
    """
    if trapped_nodes(products, strategy).size:
        raise CheckFailed("the restrictions trap the system somewhere reachable")
    game = build_agent_game(products, strategy, agent)
    result = solve_gr1(game.game)
    if not result.realizable or result.strategy is None:
        raise CheckFailed("the test agent cannot realize the restrictions (the GR(1) game is lost)")
    controller, report = checked_controller(products, strategy, agent, game, result.strategy)
    return game, controller, report


def checked_controller(
    products: Products, strategy: TestStrategy, agent: TestAgent, game: AgentGame, gr1_strategy: GR1Strategy
) -> tuple[AgentController, ClosedLoopReport]:
    """The test agent's table of a GR(1) strategy, after checking the strategy wins the game
    and the table keeps the restrictions in closed loop (restricted to the entries it uses).

    Raises
    ------
    CheckFailed
        If the strategy is not winning or fails the closed-loop check.
    """
    try:
        verify_strategy(game.game, gr1_strategy)
    except StrategyError as exc:
        raise CheckFailed(f"the test agent's GR(1) strategy is not winning: {exc}") from None
    full = controller_from_strategy(products, game, gr1_strategy, agent)
    report = verify_closed_loop(products, strategy, agent, full)
    return full.restricted(*report.entries), report
