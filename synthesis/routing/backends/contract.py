"""The one contract every backend of the routing model meets (:class:`Backend`), what one
solve of the lazy loop hands it (:class:`Round`), and the one question a backend may answer
beside its two phases (:class:`LeastQuery`, :class:`Least`). :data:`synthesis.routing.solve.SOLVERS`
is the table of backends by name."""

from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

import numpy as np

from ...graphs.products import Products
from ..certificates import CutProof
from ..model import RoutingModel
from ..options import MilpOptions
from ..phases import Phase
from ..solver_control import Clock

S = TypeVar("S")


@dataclass(frozen=True)
class Round:
    """One solve of :func:`~synthesis.routing.solve.solve_routing`'s lazy loop, as a backend's
    phases see it: the product graphs, the built model, the options (``backend`` resolved),
    the histories whose feasibility flows the model holds (``entries``), the solve's clock, and
    whether ``"auto"`` chose this backend (``by_auto``: CP-SAT then tries the hitting set)."""

    products: Products
    rm: RoutingModel
    options: MilpOptions
    entries: dict[int, np.ndarray]
    clock: Clock
    by_auto: bool = False


@dataclass(frozen=True)
class LeastQuery:
    """A question beside the two phases: the least ``cost @ x`` over the solutions ``x`` of the
    routing model ``rm`` with flow ``F >= 1`` (every row of the model, the row
    ``sum_{e out of Src} f_e >= 1`` added), the columns ``integral`` declared integral where
    the model has them continuous (their least value is integral, so the bound is), solved
    under ``options``' threads, seed and stop requests until ``deadline`` (a ``perf_counter``
    time; ``None``: no limit). ``label`` names the solve in its live status.

    What :func:`~synthesis.routing.caps.fewest.fewest_within` asks: the fewest walls (doors,
    restrictions) of any test, with ``cost`` 1 on the caps' item columns it counts."""

    rm: RoutingModel
    cost: np.ndarray
    integral: np.ndarray
    options: MilpOptions
    deadline: float | None
    label: str


@dataclass(frozen=True)
class Least:
    """The answer to a :class:`LeastQuery`: ``status`` ``"optimal"`` (``value`` the least cost),
    ``"infeasible"`` (no solution has flow >= 1), or ``"stopped"`` (the deadline ended the solve:
    ``bound`` the proven lower bound on the least cost, ``None`` where the solver proved none)."""

    status: str
    value: float | None = None
    bound: float | None = None


@dataclass(frozen=True)
class Backend(Generic[S]):
    """A solver of the routing model: the same two phases, returning the same :class:`Phase`,
    over a session ``S`` that holds the model between them (a ``highspy.Highs``, a CP-SAT child).

    The front (:func:`~synthesis.routing.solve.solve_routing`) opens ``session(round)``, runs
    ``phase1(session, round)`` (maximum flow), then ``phase2(session, round, x, flow, proof)``
    (fewest cuts at phase 1's flow ``flow``, from phase 1's solution ``x``, with the walls' cut
    bound ``proof`` where it applies), and adds ``figures(session)`` to the result's stats. Each
    phase returns a whole model solution that the backend has checked against the model.

    ``least`` answers a :class:`LeastQuery` on a model of its own (no session): provided by
    HiGHS (:func:`synthesis.routing.backends.highs.least`); ``None`` on CP-SAT, for which a
    query is answered by the first backend of the table that provides it
    (:func:`synthesis.routing.solve.solve_least`: HiGHS), so the answer is the same whichever
    backend the solve itself used.
    """

    name: str
    label: str  # how progress lines name it ("routing MILP (CP-SAT)")
    version: Callable[[], str]  # the version of the package its answers depend on
    require: Callable[[], None]  # raise ProblemError when its package is missing
    session: Callable[[Round], AbstractContextManager[S]]
    phase1: Callable[[S, Round], Phase]
    phase2: Callable[[S, Round, np.ndarray, int, CutProof | None], Phase]
    figures: Callable[[S], dict[str, Any]]  # extra stats of the solve (``{}``: none)
    least: Callable[[LeastQuery], Least] | None = None  # a LeastQuery answered (None: not provided)
