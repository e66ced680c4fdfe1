"""The options of the routing MILP (:class:`MilpOptions`) and the cut sets it must not return
(:class:`Exclusion`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .solver_control import SolveControl

MODES = ("static", "reactive", "mixed")


@dataclass(frozen=True)
class Exclusion:
    """Cut sets the routing MILP must not return: every cut set that cuts all of
    :attr:`cut` and none of :attr:`open` (cut-group keys, see :func:`cut_groups`).

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


@dataclass
class MilpOptions:
    """Options of the routing MILP.

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
        cells across fuel levels (:data:`TIE_PLACES`): ``"none"``, ``"all"`` or
        ``"static"`` (the static area only: physical walls beside a test agent's
        per-transition cuts).
    block_states
        MILP-agent: add ``d_state`` per place entered by a cut and minimise them
        before the cuts (method.md §7).
    exclusions
        Rejected cut sets (:class:`Exclusion`): each excludes every cut set that cuts
        all its ``cut`` groups and none of its ``open`` groups, with the row
        ``sum_{cut} d - sum_{open} d <= |cut| - 1``.
    time_limit
        Seconds for both phases together (``None``: no limit); with ``after_first``,
        seconds to a first test.
    after_first
        Once a first test (flow >= 1) is in hand, seconds left to improve it
        (``None``: ``time_limit`` bounds the whole solve). The paper's budget is
        ``time_limit=600, after_first=60``.
    mip_rel_gap
        Relative gap at which HiGHS may stop (reported; ``status`` is then
        ``"feasible"`` unless the gap is proven 0).
    threads
        HiGHS threads (``None``: HiGHS decides, which depends on the machine). HiGHS's
        MIP search is deterministic for fixed options, version and thread count.
    node_limit
        Branch-and-bound nodes per HiGHS run (``mip_max_nodes``; ``None``: no limit):
        a deterministic budget, unlike ``time_limit``. A run stopped by it returns its
        best test (``"feasible"``) as a time limit does.
    random_seed
        HiGHS's ``random_seed``, fixed so the search is the same on every run.
    closed_loop
        Also forbid traps at configurations that are not entry nodes (see
        :func:`solve_routing`); ``False`` (the default) gives method.md §5 exactly.
    feasibility
        When the feasibility flows (c6-c8) enter the model: ``"auto"`` (see
        :func:`solve_routing`), ``"eager"`` (all at once: one round, and every
        incumbent of a time-limited solve is trap-free) or ``"lazy"`` (where they bind).
    reductions
        Fix open, before any solve, the cut groups that :mod:`synthesis.routing.bounds.reductions`
        proves some optimum leaves open (column upper bound 0); off only to measure them.
    flow_bound
        MILP-static: lower the flow upper bound phase 1 starts from to the walls' bound of
        :mod:`synthesis.routing.bounds.flow_bound` (a proof, so the optimum is kept); off only to
        measure it.
    cut_bound
        MILP-static: at phase 2's flow level, the walls' cut bound of
        :mod:`synthesis.routing.bounds.cut_bound` (a proof) and its minimum cuts' wall sets, completed
        and checked, as a start: an answer that costs the bound is proven optimal at that
        level, with or without a search; off only to measure it.
    integral_phase2
        MILP-reactive, HiGHS's phase 2 (fewest cuts): the reachability columns ``mu`` and
        the flows ``f`` are integral there (:func:`phase2_integral_columns` proves the
        optimum is kept), so HiGHS branches on which nodes ``Src`` reaches and its
        heuristics look for integral routes, not on the cuts alone (docs/benchmarks.md,
        "MILP-reactive's fewest cuts (issue 18, session 10)"); off only to measure it. The
        other modes and phase 1 keep those columns continuous.
    flow_rows
        How the feasibility flows' closing rows (c7) are written: ``"edge"`` (method.md's, one
        row ``x + K d <= K`` per flow edge), ``"cut"`` (one row per history and closing cut
        column over all the flow edges it closes, :func:`_add_feasibility` proves the same
        answers) or ``"auto"`` (the default: ``"cut"`` where
        :func:`synthesis.routing.milp.per_cut_flow_rows` says it was measured to pay, else
        ``"edge"``).
    offer_starts
        Offer HiGHS the heuristic's answer (phase 1) and the phase-1 answer (phase 2) as
        starts (each checked against the model first). Without, they are still kept as
        the fallback answers of a time-limited solve. (``experiments.lab.bench_starts``
        measures both.)
    control
        Shared with the caller while HiGHS runs: Ctrl-C / stop requests, and the live
        status (best answer, bound, gap) a progress line shows (see
        :mod:`synthesis.routing.solver_control`).
    backend
        The solver of the model (:data:`BACKENDS`): ``"highs"`` (HiGHS's branch and cut),
        ``"cpsat"`` (OR-Tools CP-SAT in a child process: :mod:`synthesis.routing.backends.cpsat`),
        or ``"auto"`` (the default:
        :func:`synthesis.routing.milp.auto_backend` decides on the built model).
    work_limit
        CP-SAT's budget per phase in its deterministic seconds (``max_deterministic_time``;
        ``None``: no limit): a deterministic budget, as ``node_limit`` is for HiGHS. A run
        stopped by it returns its best test (``"feasible"``).
    caps
        Caps on the physical restrictions a test may use (``max_walls``, ``max_doors``,
        ``max_restrictions``; :func:`physical_items` says what one is): rows of the model
        (:func:`_add_caps`), lazy rows of the hitting set's separator
        (:meth:`~synthesis.routing.backends.separator.CoverSeparator.separate`). With a cap the
        dominance reduction is off (its proof swaps one cut group for another, which may
        add a physical restriction).
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
    time_limit: float | None = None
    after_first: float | None = None
    mip_rel_gap: float = 0.0
    threads: int | None = None
    progress: Callable[[str], None] | None = None
    closed_loop: bool = False
    feasibility: str = "auto"
    node_limit: int | None = None
    random_seed: int = 0
    control: SolveControl | None = None
    offer_starts: bool = True
    reductions: bool = True
    flow_bound: bool = True
    cut_bound: bool = True
    integral_phase2: bool = True
    flow_rows: str = "auto"
    backend: str = "auto"
    work_limit: float | None = None
    caps: dict[str, int] = field(default_factory=dict)
    one_way_walls: bool = True

    @property
    def deterministic(self) -> bool:
        """Whether the answer depends only on the problem, these options and the versions:
        no wall-clock limit, and a fixed thread count (design.md, "Determinism")."""
        return self.time_limit is None and self.after_first is None and bool(self.threads)
