"""A GR(1)-synthesized system under test (``gr1``), re-synthesized when restrictions change.

The controller is a winning strategy of an explicit GR(1) game solved with
:func:`synthesis.test_agent.gr1.solver.solve` (and checked with :func:`synthesis.test_agent.gr1.verify.verify_strategy`):

* **positions** — the nodes ``(s, q_sys)`` of the SUT's own product graph
  ``G_sys = T x B_sys`` (:class:`flowtest_env.system_product.SystemProduct`); the hidden test
  objective is not part of it;
* **environment** (the test) — at each position it makes the one choice the SUT assumes
  it makes: the restrictions the SUT knows of (the static walls, which every
  observation shows, and the reactive restrictions it has seen and not yet seen lifted);
* **system** (the controller) — answers with a successor along a move that is not
  restricted (or a stay); accepting nodes of ``B_sys`` are absorbing;
* **guarantee** — ``G F accepting`` (with absorbing acceptance: reach the goal while
  meeting the whole system objective — fuel, safety, reactions are in ``B_sys``, and
  positions from which it cannot be met are outside the winning region, so the
  controller never enters them).

Assumptions on the test environment (the controller is correct only under them):

1. **restrictions are observed before committing** — the SUT sees the restrictions of
   its current state (the action mask) before it moves, and the test does not restrict
   a move the SUT has already committed to;
2. **restrictions persist until seen lifted** — a restriction seen once is assumed to
   stay (the tests' restrictions depend on the history, which changes only when the
   SUT makes progress on the test objective); when the SUT sees it lifted it drops it;
3. **the tester never blocks every path forever** — from the SUT's state some way to its
   goal stays open (docs/method.md's feasibility, and (g8) for a test agent: it never stays
   two steps in a row on a cell that blocks every path).

Because the test is reactive, no *fixed* controller is winning for every restriction
pattern the test may show; as in the paper's hardware runs, the controller is
**re-synthesized whenever the known restrictions change**. Syntheses are cached by
the set of known restrictions. If the known restrictions leave no winning strategy,
the ones not visible now are dropped (assumption 2 failed); if even the visible ones
leave none, the tester is blocking every path now and the SUT waits (assumption 3
says it will not last).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from flowtest_env.system_product import SystemProduct
from synthesis.test_agent.gr1.game import GR1Game
from synthesis.test_agent.gr1.solver import solve
from synthesis.test_agent.gr1.strategy import GR1Strategy
from synthesis.test_agent.gr1.verify import verify_strategy

from .base import Policy
from .planning import Tracked, safe_wait

Blocked = frozenset[tuple[int, int]]


def synthesize_controller(product: SystemProduct, blocked: Blocked, start: int, verify: bool = False) -> GR1Strategy | None:
    """Solve the reach game on ``G_sys`` minus ``blocked`` from node ``start``.

    Returns
    -------
    GR1Strategy or None
        The winning strategy (choice ``v`` = position ``v``), ``None`` if not realizable.
    """
    nxt = product.next_node
    n = nxt.shape[0]
    nq = product.n_q
    ptr = [0]
    succ: list[int] = []
    for v in range(n):
        if product.accepting[v]:
            succ.append(v)  # absorbing acceptance
        else:
            s = v // nq
            for a in range(nxt.shape[1]):
                w = int(nxt[v, a])
                if w >= 0 and (s, a) not in blocked:
                    succ.append(w)
        ptr.append(len(succ))
    game = GR1Game(
        n_positions=n,
        choice_owner=np.arange(n, dtype=np.int64),
        choice_succ_ptr=np.asarray(ptr, dtype=np.int64),
        choice_succ=np.asarray(succ, dtype=np.int64),
        initial=[np.asarray([start], dtype=np.int64)],
        env_liveness=[],
        sys_liveness=[product.accepting.copy()],
    )
    result = solve(game)
    if not result.realizable or result.strategy is None:
        return None
    if verify:
        verify_strategy(game, result.strategy)
    return result.strategy


class GR1SUT(Tracked):
    """The GR(1)-synthesized SUT (see the module docstring)."""

    def __init__(self, env: Any, verify: bool = False) -> None:
        super().__init__(env)
        self.verify = verify
        self.memory = 0
        self._strategies: dict[tuple[Blocked, int], GR1Strategy | None] = {}
        self.syntheses = 0

    def reset(self, seed: int | None = None) -> None:
        old = self.product
        super().reset(seed)
        if self.product is not old:
            self._strategies = {}
        self.memory = 0

    def _controller(self, blocked: Blocked, v: int) -> GR1Strategy | None:
        # a strategy for `blocked` wins from every node of its winning region; keep one per
        # (blocked, start) only when the cached one does not win from v
        key = (blocked, -1)
        strat = self._strategies.get(key)
        if strat is not None and strat.next_position[0, v] >= 0:
            return strat
        key = (blocked, v)
        if key not in self._strategies:
            assert self.product is not None
            self.syntheses += 1
            self._strategies[key] = synthesize_controller(self.product, blocked, v, self.verify)
            if (blocked, -1) not in self._strategies:
                self._strategies[(blocked, -1)] = self._strategies[key]
        return self._strategies[key]

    def act(self, observation: Any, info: dict[str, Any]) -> int:
        game, prod, v, mask, now = self._situation(observation, info)
        strat = self._controller(frozenset(self.known), v)
        if strat is None or strat.next_position[0, v] < 0:
            self.known = now
            strat = self._controller(frozenset(self.known), v)
        if strat is None or strat.next_position[0, v] < 0:
            return safe_wait(game, prod, v, mask, prod.distances())
        w, self.memory = strat.move(0, v)
        for a in range(game.n_actions):
            if mask[a] and prod.next_node[v, a] == w:
                return a
        return safe_wait(game, prod, v, mask, prod.distances())  # pragma: no cover - strategy uses legal moves


def make_gr1(env: Any, arg: str) -> Policy:
    """The GR(1) SUT for ``env`` (``gr1``; ``gr1:verify`` checks every synthesized strategy)."""
    policy = GR1SUT(env, verify=arg == "verify")
    policy.reset(None)
    return policy
