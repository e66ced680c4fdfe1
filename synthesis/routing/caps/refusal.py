"""A cap below what every test needs, refused before the solve (:func:`check_caps_reachable`):
by the bypass counts of :mod:`synthesis.routing.caps.bypasses` and the per-history separations of
:mod:`synthesis.routing.caps.separations`, whose proven bounds it returns for the message of a
solve the time limit ends with neither a test nor a proof.
"""

from __future__ import annotations

import time

from ...graphs.products import Products
from ...model.errors import InconsistentProblem
from ..options import MilpOptions
from .bypasses import BypassGraph, bypass_graph, count_disjoint_bypasses, routed_bypasses
from .messages import CAP_NOUNS, caps_text
from .separations import HistorySeparations

ROUTED_SHARE = 0.25
"""The share of a synthesis's time limit
:func:`~synthesis.routing.caps.bypasses.routed_bypasses` may take before the solve."""


def check_caps_reachable(products: Products, options: MilpOptions) -> dict[str, int]:
    """Refuse caps below what the problem needs before any solve: a cap ``N`` below
    :func:`~synthesis.routing.caps.bypasses.disjoint_bypasses` (``N + 1`` walks around the test
    objective that share no item it counts) admits no test, nor does one below
    :func:`~synthesis.routing.caps.bypasses.routed_bypasses` (the same count with the route
    every test leaves open spared, branched over its first and last moves), nor one that
    :class:`~synthesis.routing.caps.separations.HistorySeparations` refutes (what a test must
    close under one history while leaving the system a way to its goal: the feasibility flows
    the bypass counts leave out).

    Returns the proven lower bound of each cap (:func:`proven_bound`), for the message of a
    solve the time limit ends with neither a test nor a proof.

    Raises
    ------
    InconsistentProblem
        ``"unroutable"``, naming the cap and the walks that prove it.
    """
    bounds: dict[str, int] = {}
    for cap, limit in options.caps.items():
        noun = CAP_NOUNS[cap].split(" (")[0]
        bg = bypass_graph(products, options, cap)  # built once for both bounds
        walks = count_disjoint_bypasses(bg, stop_above=limit)
        if walks > limit:
            raise InconsistentProblem(
                "unroutable",
                f"no test with {caps_text({cap: limit})} routes every successful execution through the test objective: "
                f"at least {walks} {noun} are needed ({walks} ways from the start to the goal around the test objective "
                f"share no {noun[:-1]} this cap counts, and a test must close each); raise the cap or drop it",
            )
        deadline = None if options.time_limit is None else time.perf_counter() + ROUTED_SHARE * options.time_limit
        bounds[cap] = proven_bound(products, options, cap, limit, walks, deadline, bg)
        if bounds[cap] > limit:
            raise InconsistentProblem(
                "unroutable",
                f"no test with {caps_text({cap: limit})} routes every successful execution through the test objective: "
                f"at least {limit + 1} {noun} are needed (whatever way through the test objective a test leaves open, "
                f"{limit + 1} ways from the start to the goal around the test objective share no {noun[:-1]} off that way, "
                f"and a test must close each); raise the cap or drop it",
            )
        separations = HistorySeparations(products, options, cap)  # built once for every bound tried
        while bounds[cap] <= limit and separations.exceed(bounds[cap], deadline=deadline):
            bounds[cap] += 1
        if bounds[cap] > limit:
            raise InconsistentProblem(
                "unroutable",
                f"no test with {caps_text({cap: limit})} routes every successful execution through the test objective: "
                f"at least {limit + 1} {noun} are needed (under a history the system must pass on any way through the "
                f"test objective, a test must close every way to the goal that keeps that history while leaving the "
                f"system a way to the goal, and that takes more than {limit} {noun} whichever way is left); "
                f"raise the cap or drop it",
            )
    return bounds


def proven_bound(
    products: Products,
    options: MilpOptions,
    cap: str,
    limit: int,
    plain: int,
    deadline: float | None = None,
    bg: BypassGraph | None = None,
) -> int:
    """The largest ``k <= limit + 1`` proven by
    :func:`~synthesis.routing.caps.bypasses.routed_bypasses` to be needed (``plain``,
    :func:`~synthesis.routing.caps.bypasses.disjoint_bypasses`'s count, where it proves nothing
    more): ``limit + 1`` where no test fits the cap. Proves ``k + 1`` for ``k = plain, plain + 1, ...`` and stops at the
    first it cannot prove (a search that cannot prove ``k + 1`` cannot prove more, so this
    costs little more than the one search for ``limit + 1``), by ``deadline``. ``bg``: the
    :func:`~synthesis.routing.caps.bypasses.bypass_graph`, where the caller has it already."""
    best = max(plain, 0)
    if bg is None:
        bg = bypass_graph(products, options, cap)  # built once for every k
    while best <= limit:
        if routed_bypasses(products, options, cap, stop_above=best, deadline=deadline, bg=bg) <= best:
            break
        best += 1
    return best
