"""What phase 1 of every backend starts from (:func:`phase1_start`): the routing heuristic's test
as a whole model solution (under caps, a test within them where the heuristic's is over one),
and phase 1's answer itself where that start, or a checked candidate of the walls' cut bound,
already attains the flow upper bound, so no solver runs."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..bounds.heuristic import RoutingGuess
from ..caps.start import start_within_caps
from ..certificates import test_at_bound
from ..phases import Phase, guess_solution, trap_test
from .contract import Round


@dataclass(frozen=True)
class Phase1Start:
    """``guess``: the heuristic's test (its flow and proven upper bound); ``x``: it as a whole
    model solution (``None``: unusable, see :func:`~synthesis.routing.phases.guess_solution`);
    ``proven``: phase 1's answer where it is proven before any solver runs, else ``None``."""

    guess: RoutingGuess
    x: np.ndarray | None
    proven: Phase | None


def phase1_start(r: Round) -> Phase1Start:
    """The start of phase 1 on ``r``: the heuristic's test (no entry node of ``r.entries``
    trapped), within the caps (:func:`~synthesis.routing.caps.start.start_within_caps`, by the
    clock's deadline). It is proven the maximum flow where it attains the heuristic's upper
    bound; else (MILP-static) a checked candidate of the walls' cut bound at that bound
    (:func:`~synthesis.routing.certificates.test_at_bound`) is. Either starts the clock's
    ``after_first`` budget.

    Example (a backend's phase 1)::

        start = phase1_start(r)
        if start.proven is not None:
            return start.proven
    """
    rm, products, options, entries, clock = r.rm, r.products, r.options, r.entries, r.clock
    guess = rm.guess(products, traps=trap_test(products, rm.groups, entries))
    x_guess = guess_solution(products, rm, guess, options)
    guess, x_guess = start_within_caps(products, rm, options, entries, guess, x_guess, clock.deadline)
    if x_guess is not None:
        clock.first_test()
    if x_guess is not None and guess.flow == guess.upper_bound:
        return Phase1Start(guess, x_guess, Phase(x_guess, "optimal", 0.0, None))  # the flow upper bound is attained: proven
    x_top = test_at_bound(products, rm, options, entries, guess.upper_bound)
    if x_top is not None:
        clock.first_test()
        return Phase1Start(guess, x_guess, Phase(x_top, "optimal", 0.0, None))  # a cut bound candidate attains the flow upper bound
    return Phase1Start(guess, x_guess, None)
