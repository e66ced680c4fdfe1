"""What to say where no test fits the caps: the fewest items a test needs
(:func:`fewest_within`, the routing model's own optimum, solved through a backend's ``least``
capability of :class:`~synthesis.routing.backends.contract.Backend`), and how many a test the
capped search finds uses (:func:`found_with`), so the user can tell a cap too tight from a time
limit too short.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from ...graphs.consistency import check_consistency
from ...graphs.products import Products
from ..backends.contract import LeastQuery
from ..model import build_model
from ..options import MilpOptions
from ..result import required_entries
from ..solve import solve_least
from .start import capped_guess, fewer_items

FEWEST_SECONDS = 30.0
"""The most seconds :func:`fewest_within` spends when the caller gives no deadline."""

FOUND_SECONDS = 15.0
"""The most seconds :func:`found_with` may take where a capped solve ended with neither a test
nor a proof (its budgets are deterministic and end it sooner: about 4 s for walls and 10 s for
doors on the 30x30 rack floor)."""

FOUND_SHARE = 0.1
"""The share of a capped synthesis's time limit kept back from the solve for :func:`found_with`
(at most :data:`FOUND_SECONDS`), so the limit holds for the message too."""


@dataclass(frozen=True)
class Fewest:
    """The fewest items a cap counts that a test needs: ``value`` exactly when ``exact``,
    else at least ``value`` (``None``: no test at all, whatever the cap)."""

    value: int | None
    exact: bool
    timed_out: bool = False  # not exact because the deadline ended the solve (else: a relaxation's optimum)

    def text(self, noun: str) -> str:
        """``"the fewest is 5 doors"``, ``"at least 5 doors are needed"``."""
        if self.value is None:
            return f"no test routes it with any number of {noun}"
        if not self.exact and self.value == 0:
            return f"how many {noun} would do was not settled within the time left"
        if self.exact:
            return f"the fewest that does is {self.value} {noun}"
        if self.timed_out:
            return f"at least {self.value} {noun} are needed (not proven exactly within the time left)"
        return f"at least {self.value} {noun} are needed"


def fewest_within(products: Products, options: MilpOptions, cap: str, deadline: float | None = None) -> Fewest:
    """The fewest items ``cap`` counts over the cut sets with flow >= 1 that meet every other
    cap of ``options.caps`` and every row of the routing model (feasibility flows of every
    history with entry nodes, up front: no lazy rounds). ``deadline`` (``perf_counter``
    time; default :data:`FEWEST_SECONDS` from now) bounds the solve; stopped by it, the
    answer is the solver's proven lower bound (``exact`` false). The model is solved by
    ``options.backend`` where it provides the backend contract's ``least``, else by the first
    backend that does (:func:`~synthesis.routing.solve.solve_least`: HiGHS). With
    ``closed_loop`` or the test agent's places the model is a relaxation of the test's
    conditions, so the answer is a lower bound too."""
    if deadline is None:
        deadline = time.perf_counter() + FEWEST_SECONDS
    caps = {k: v for k, v in options.caps.items() if k != cap}
    caps[cap] = 10**9  # present, so its items have columns; never binding
    opts = replace(options, caps=caps, exclusions=list(options.exclusions))
    entries = required_entries(products, opts)
    rm = build_model(products, opts, entries, check_consistency(products))
    rows = rm.caps
    if rows is None:  # cannot happen: caps is not empty
        raise RuntimeError("the routing model has no cap rows")
    counted = rows.items.kinds(cap) & (rows.item_col >= 0)
    cost = np.zeros(rm.n_col)
    cost[rows.item_col[counted]] = 1.0
    # the item columns are integral at their least value; declared so, the solver's bound is integral
    integral = rows.item_col[rows.item_col >= 0]
    least = solve_least(options.backend, LeastQuery(rm, cost, integral, options, deadline, "the fewest restrictions a test needs"))
    if least.status == "infeasible":
        return Fewest(None, True)
    if least.status == "optimal" and least.value is not None:
        relaxed = options.closed_loop or options.block_states
        return Fewest(int(round(least.value)), not relaxed)
    bound = least.bound
    return Fewest(max(int(np.ceil(bound - 1e-6)), 0) if bound is not None else 0, False, timed_out=True)


def found_with(products: Products, options: MilpOptions, cap: str, deadline: float | None = None) -> int | None:
    """How many items ``cap`` counts a test uses that
    :func:`~synthesis.routing.caps.start.capped_guess` finds under ``options.caps`` (every
    feasibility flow up front, as :func:`fewest_within`), where none fits: the test over the
    caps with the fewest items they count that its search met
    (:func:`~synthesis.routing.caps.start.fewer_items` applied), so a cap the user can ask for
    and get a test, for the message of a capped solve that the time limit ended with neither a test nor a proof.
    ``None`` where the search finds none (by ``deadline``, a ``perf_counter`` time). Not the
    fewest: an upper bound on it, next to the proven lower bound. Deterministic (the
    search's budgets), so the same problem names the same cap on every machine.

    Example::

        n = found_with(products, milp, "max_walls")  # 9 on the 30x30 rack floor under --max-walls 7
    """
    opts = replace(options, exclusions=list(options.exclusions))
    entries = dict(required_entries(products, opts))
    rm = build_model(products, opts, entries, check_consistency(products))
    guess = capped_guess(products, rm, opts, entries, deadline, keep_best=True)
    if guess is None or rm.caps is None:
        return None
    used = np.zeros(rm.caps.items.is_wall.size, dtype=bool)
    used[rm.caps.items.of_group[fewer_items(products, rm, opts, guess.cut_groups, entries, deadline)]] = True
    return int((used & rm.caps.items.kinds(cap)).sum())
