"""The routing model's options in four groups, and the one check of them all.

:class:`ModelOptions` say what the model is (they change the answer), :class:`Budgets` how much
a solve may spend, :class:`MeasurementSwitches` turn off the parts that speed a solve without
changing its answer (only to measure what each buys), and :class:`RunOptions` say how a solve
runs (which solver, its progress lines, the caller's stop button). :class:`MilpOptions` is the
four together, each field under its own name, so ``MilpOptions(time_limit=60)``,
``options.time_limit`` and ``replace(options, flow_bound=False)`` read as they always did. The
synthesis options (:class:`synthesis.pipeline.SynthesisOptions`) are the budgets and run options
of these same classes, not a copy of them.

:func:`check_options` checks any of them by one table, :data:`RULES`, one rule per field; the
rules (:mod:`synthesis.model.option_rules`) are the ones a problem file and the command line
use too, so the same bad value gets the same reason wherever it is typed.

Example
-------
>>> options = MilpOptions(mode="static", time_limit=60.0, threads=1)
>>> check_options(options)
>>> group_of(options, Budgets).time_limit
60.0
>>> from dataclasses import replace
>>> check_options(replace(options, threads=0))
Traceback (most recent call last):
...
synthesis.model.errors.ProblemError: option threads must be an integer from 1 to 256, not 0
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields
from typing import Any, TypeVar

import numpy as np

from ..model.option_rules import COUNT, FLAG, GAP, SECONDS, SEED, THREADS, WORK, Rule, choice, instance_of
from ..problems.problem import CAP_KEYS, TIE_PLACES, check_caps
from .solve_status import SolveControl

MODES = ("static", "reactive", "mixed")
"""The routing model's modes (``MilpOptions.mode``): MILP-static, MILP-reactive, MILP-mixed."""

BACKENDS = ("auto", "highs", "cpsat")
"""The solvers of the routing model (``MilpOptions.backend``; ``flowtest synthesize --backend``)."""

FLOW_ROWS = ("auto", "edge", "cut")
"""How the feasibility flows' closing rows are written (``MilpOptions.flow_rows``)."""

FEASIBILITY = ("auto", "eager", "lazy")
"""When the feasibility flows enter the model (``MilpOptions.feasibility``)."""


@dataclass(frozen=True)
class Exclusion:
    """Cut sets the routing MILP must not return: every cut set that cuts all of
    :attr:`cut` and none of :attr:`open` (cut-group keys, see :func:`~synthesis.routing.groups.cut_groups`).

    A rejected cut set ``C`` alone is ``Exclusion(C)``; the counterexample loop of
    :mod:`synthesis.test_agent.loop` excludes, with the reason the agent lost
    (:mod:`synthesis.test_agent.reasons`), a small core of ``C`` and the groups that must stay
    open for the reason to hold.
    """

    cut: tuple[int, ...]
    open: tuple[int, ...] = ()

    def excludes(self, cut_keys: set[int]) -> bool:
        """Whether the cut set with these group keys is excluded."""
        return set(self.cut) <= cut_keys and not cut_keys.intersection(self.open)


@dataclass(frozen=True, kw_only=True)
class ModelOptions:
    """What the routing model is: these options change its answer (docs/method.md §5, §7).

    Attributes
    ----------
    mode
        ``"static"`` (c9 on every transition), ``"reactive"`` (c1-c8) or ``"mixed"``
        (c1-c8, c9 on ``static_moves``).
    static_moves
        ``bool`` mask over the moves of T: the static area of a mixed problem.
    bidirectional
        c14: a cut on ``s -> s'`` also cuts ``s' -> s`` (under the same history).
    tie_places
        Which cuts are tied between places (cells) rather than states, one per pair of
        cells across fuel levels (:data:`~synthesis.problems.problem.TIE_PLACES`): ``"none"``,
        ``"all"`` or ``"static"`` (the static area only: physical walls beside a test agent's
        per-transition cuts).
    block_states
        MILP-agent: add ``d_state`` per place entered by a cut and minimise them
        before the cuts (docs/method.md §7).
    exclusions
        Rejected cut sets (:class:`Exclusion`): each excludes every cut set that cuts
        all its ``cut`` groups and none of its ``open`` groups, with the row
        ``sum_{cut} d - sum_{open} d <= |cut| - 1``.
    closed_loop
        Also forbid traps at configurations that are not entry nodes (see
        :func:`~synthesis.routing.solve.solve_routing`); ``False`` (the default) gives
        docs/method.md §5 exactly.
    caps
        Caps on the physical restrictions a test may use (``max_walls``, ``max_doors``,
        ``max_restrictions``; :func:`~synthesis.routing.groups.physical_items` says what one is):
        rows of the model, lazy rows of the hitting set's separator. With a cap the dominance
        reduction is off (its proof swaps one cut group for another, which may add a physical
        restriction).
    one_way_walls
        Whether a static restriction may block a move while the move back stays open. Off,
        the two directions of a move in the static area share one cut (a wall blocks both
        ways), and a static move whose move back lies outside the static area cannot be
        restricted at all (the wall would be one-way). On (the default here, and for the
        built-in problems: their shipped answers), walls follow ``bidirectional`` alone.
        Problem files default to off (``one_way_walls`` in ``[environment]``).
    """

    mode: str = "reactive"
    static_moves: np.ndarray | None = None
    bidirectional: bool = False
    tie_places: str = "none"
    block_states: bool = False
    exclusions: list[Exclusion] = field(default_factory=list)
    closed_loop: bool = False
    caps: dict[str, int] = field(default_factory=dict)
    one_way_walls: bool = True


@dataclass(frozen=True, kw_only=True)
class Budgets:
    """How much a solve may spend. A wall-clock budget makes the answer depend on the machine;
    a node or work budget does not (:attr:`MilpOptions.deterministic`). A solve stopped by any
    of them returns its best test (``"feasible"``, with its gap).

    Attributes
    ----------
    time_limit
        Seconds for both phases together (``None``: no limit); with ``after_first``,
        seconds to a first test. A synthesis's ``None`` is the problem's ``time_limit``.
    after_first
        Once a first test (flow >= 1) is in hand, seconds left to improve it
        (``None``: ``time_limit`` bounds the whole solve). The paper's budget is
        ``time_limit=600, after_first=60``.
    mip_rel_gap
        Relative gap at which the solver may stop (reported; ``status`` is then
        ``"feasible"`` unless the gap is proven 0).
    node_limit
        Branch-and-bound nodes per HiGHS run (``mip_max_nodes``; ``None``: no limit): a
        deterministic budget, unlike ``time_limit``.
    work_limit
        CP-SAT's budget per phase in its deterministic seconds (``max_deterministic_time``;
        ``None``: no limit): a deterministic budget, as ``node_limit`` is for HiGHS.
    threads
        HiGHS threads. ``None``: HiGHS decides here, which depends on the machine; a synthesis
        (:func:`synthesis.pipeline.milp_options`) makes it 1, so its answer is the same on
        every machine (HiGHS's MIP search is deterministic for a fixed thread count).
    random_seed
        The solver's random seed, fixed so the search is the same on every run.
    """

    time_limit: float | None = None
    after_first: float | None = None
    mip_rel_gap: float = 0.0
    node_limit: int | None = None
    work_limit: float | None = None
    threads: int | None = None
    random_seed: int = 0


@dataclass(frozen=True, kw_only=True)
class MeasurementSwitches:
    """Parts of the solve that make it faster and keep its answer (each a proof, or a choice
    measured to pay where it is made). Each is on (or ``"auto"``) unless someone measures what
    it buys: the lab's scripts (``experiments/lab/bench_*.py``) turn them off.

    Attributes
    ----------
    reductions
        Fix open, before any solve, the cut groups that :mod:`synthesis.routing.bounds.reductions`
        proves some optimum leaves open (column upper bound 0).
    flow_bound
        MILP-static: lower the flow upper bound phase 1 starts from to the walls' bound of
        :mod:`synthesis.routing.bounds.flow_bound` (a proof, so the optimum is kept).
    cut_bound
        MILP-static: at phase 2's flow level, the walls' cut bound of
        :mod:`synthesis.routing.bounds.cut_bound` (a proof) and its minimum cuts' wall sets,
        completed and checked, as a start: an answer that costs the bound is proven optimal at
        that level, with or without a search.
    integral_phase2
        MILP-reactive, HiGHS's phase 2 (fewest cuts): the reachability columns ``mu`` and
        the flows ``f`` are integral there (:func:`~synthesis.routing.model.phase2_integral_columns`
        proves the optimum is kept), so HiGHS branches on which nodes ``Src`` reaches and its
        heuristics look for integral routes, not on the cuts alone (docs/benchmarks/solvers.md,
        "MILP-reactive's phase 2"). The other modes and phase 1 keep those columns continuous.
    offer_starts
        Offer HiGHS the heuristic's answer (phase 1) and the phase-1 answer (phase 2) as
        starts (each checked against the model first). Without, they are still kept as
        the fallback answers of a time-limited solve.
    flow_rows
        How the feasibility flows' closing rows (c7) are written: ``"edge"`` (docs/method.md's,
        one row ``x + K d <= K`` per flow edge), ``"cut"`` (one row per history and closing cut
        column over all the flow edges it closes: the same answers) or ``"auto"`` (``"cut"``
        where :func:`synthesis.routing.backends.rules.per_cut_flow_rows` says it was measured to pay,
        else ``"edge"``).
    feasibility
        When the feasibility flows (c6-c8) enter the model: ``"auto"`` (see
        :func:`~synthesis.routing.solve.solve_routing`), ``"eager"`` (all at once: one round, and
        every incumbent of a time-limited solve is trap-free) or ``"lazy"`` (where they bind).
    """

    reductions: bool = True
    flow_bound: bool = True
    cut_bound: bool = True
    integral_phase2: bool = True
    offer_starts: bool = True
    flow_rows: str = "auto"
    feasibility: str = "auto"


@dataclass(frozen=True, kw_only=True)
class RunOptions:
    """How a solve runs: which solver, and what it shares with its caller while it runs.

    Attributes
    ----------
    backend
        The solver of the model (:data:`BACKENDS`): ``"highs"`` (HiGHS's branch and cut),
        ``"cpsat"`` (OR-Tools CP-SAT in a child process: :mod:`synthesis.routing.backends.cpsat`),
        or ``"auto"`` (the default: :func:`synthesis.routing.backends.rules.auto_backend` decides on the
        built model).
    progress
        Called with a line of text at each stage of the solve (``None``: silent).
    control
        Shared with the caller while the solver runs: Ctrl-C / stop requests, and the live
        status (best answer, bound, gap) a progress line shows
        (:mod:`synthesis.routing.solver_control`).
    """

    backend: str = "auto"
    progress: Callable[[str], None] | None = None
    control: SolveControl | None = None


@dataclass(frozen=True, kw_only=True)
class MilpOptions(ModelOptions, Budgets, MeasurementSwitches, RunOptions):
    """Options of the routing MILP: :class:`ModelOptions`, :class:`Budgets`,
    :class:`MeasurementSwitches` and :class:`RunOptions` together, each field by its own name
    (each group's docstring says what its fields do). A frozen value: change one with
    :func:`dataclasses.replace`.

    Example
    -------
    >>> from dataclasses import replace
    >>> options = MilpOptions(mode="static", node_limit=1000, threads=1)
    >>> options.deterministic, replace(options, time_limit=5.0).deterministic
    (True, False)
    """

    @property
    def deterministic(self) -> bool:
        """Whether the answer depends only on the problem, these options and the versions:
        no wall-clock limit, and a fixed thread count (design.md, "Determinism")."""
        return self.time_limit is None and self.after_first is None and bool(self.threads)


G = TypeVar("G")


def group_of(options: object, group: type[G]) -> G:
    """The fields of ``group`` (:class:`Budgets`, ...) that ``options`` holds, as a ``group``.

    >>> group_of(MilpOptions(time_limit=3.0), Budgets).time_limit
    3.0
    """
    return group(**{f.name: getattr(options, f.name) for f in fields(group)})  # type: ignore[arg-type]


def values_of(options: object, group: Any) -> dict[str, Any]:
    """The fields of ``group`` that ``options`` holds, by name (to pass on as keywords).

    >>> values_of(MilpOptions(backend="highs"), RunOptions)
    {'backend': 'highs', 'progress': None, 'control': None}
    """
    return {f.name: getattr(options, f.name) for f in fields(group)}


def default_of(group: Any, name: str) -> Any:
    """The default of ``group``'s field ``name``: for an options class that offers one field of a
    group without the rest (the synthesis options' ``closed_loop``), so the default is the
    group's, not a copy.

    >>> default_of(ModelOptions, "closed_loop")
    False
    """
    (found,) = (f for f in fields(group) if f.name == name)
    return found.default


CAPS = instance_of(dict, f"a dict of {', '.join(CAP_KEYS)}", optional=False)

RULES: Mapping[str, Rule] = {
    # the model
    "mode": choice("routing mode", MODES),
    "static_moves": instance_of(np.ndarray, "a boolean mask over the moves or None"),
    "bidirectional": FLAG,
    "tie_places": choice("tie_places", TIE_PLACES),
    "block_states": FLAG,
    "exclusions": instance_of(list, "a list of Exclusion", optional=False),
    "closed_loop": FLAG,
    "caps": CAPS,
    "one_way_walls": FLAG,
    # the budgets
    "time_limit": SECONDS,
    "after_first": SECONDS,
    "mip_rel_gap": GAP,
    "node_limit": COUNT,
    "work_limit": WORK,
    "threads": THREADS,
    "random_seed": SEED,
    # the measurement switches
    "reductions": FLAG,
    "flow_bound": FLAG,
    "cut_bound": FLAG,
    "integral_phase2": FLAG,
    "offer_starts": FLAG,
    "flow_rows": choice("flow_rows option", FLOW_ROWS),
    "feasibility": choice("feasibility option", FEASIBILITY),
    # how it runs
    "backend": choice("solver backend", BACKENDS),
    "progress": Rule("a function of one string or None", callable, optional=True),
    "control": instance_of(SolveControl, "a SolveControl or None"),
}
"""The rule of each field of :class:`MilpOptions` (the synthesis options add theirs:
:data:`synthesis.pipeline.SYNTHESIS_RULES`)."""


def check_options(options: Any, rules: Mapping[str, Rule] = RULES) -> None:
    """Refuse a bad option before any work: each field of ``options`` (a dataclass:
    :class:`MilpOptions`, :class:`~synthesis.pipeline.SynthesisOptions`) by its rule in
    ``rules``, then the caps' keys and values.

    Raises
    ------
    ProblemError
        Naming the option and the reason (``option threads must be an integer from 1 to 256,
        not 0``): a :class:`ValueError` too.
    """
    for f in fields(options):
        err = rules[f.name].error(getattr(options, f.name), f"option {f.name}")
        if err is not None:
            raise err
    caps = getattr(options, "caps", None)
    if caps:
        check_caps(caps, " (option caps)")
