"""Explicit-state GR(1) game solver with executable finite-memory strategies.

This module solves *explicit* (enumerated) GR(1) games with integer-indexed
numpy arrays.  It is used by FlowTest wherever a test strategy has to be
synthesised from a finite game graph, and it is written so that games with
~10^5 positions and ~10^6 moves are solved in about a second: every fixpoint
step is a vectorised operation over CSR arrays (sparse matrix-vector
products, ``np.bincount``, ``np.minimum.reduceat``, fancy indexing), and the attractor-like inner
fixpoints are computed with per-choice counters that are updated frontier by
frontier, so no fixpoint contains a per-position Python loop.

Game model and semantics
------------------------
A :class:`GR1Game` is an alternating game played in *rounds*.  A round starts
at a **position** ``v``:

1. the **environment** picks one of the *choices* ``c`` with
   ``choice_owner[c] == v``;
2. the **system** (the player we synthesise for) picks a successor position
   from ``choice_succ[choice_succ_ptr[c]:choice_succ_ptr[c + 1]]``.

Conventions at dead ends:

* a position without environment choices is *winning for the system* (the
  environment cannot move, i.e. it violated its safety assumption);
* a choice without successors is *losing for the system* (the system cannot
  respond, i.e. it violated its safety guarantee).

Infinite plays are judged at round boundaries (on positions) by the GR(1)
condition ``(AND_i GF J^e_i) -> (AND_j GF J^s_j)``.  An empty list of
environment liveness sets means "no assumption" (``true``); an empty list of
system liveness sets means the single guarantee ``GF true`` (a pure safety
game).  The initial condition is a list of *groups*: the environment picks a
group, then the system picks a position inside it; the game is realizable iff
**every** group contains at least one winning position (an ``forall env
exists sys`` initial condition; an empty list of groups is vacuously
realizable, an empty group is unrealizable).

Algorithm
---------
:func:`solve` evaluates the Piterman-Pnueli-Sa'ar triple fixpoint::

    Z = nu Z. AND_j mu Y. OR_i nu X. (J^s_j & cpre(Z)) | cpre(Y) | (!J^e_i & cpre(X))

where ``cpre(S)`` is the set of positions from which, for every environment
choice, the system has a successor in ``S`` (positions without choices
belong to every ``cpre(S)``).  ``nu Z`` is iterated Gauss-Seidel style.  The
inner ``mu Y`` is reached by alternating a cheap *closure* step (the system
attractor of ``Y``, computed layer by layer with incremental counters) and a
*persistence* step (one ``nu X``, computed as the complement of an
environment attractor, per assumption).  Every batch of positions added to
``Y`` receives the next *rank*; ranks and the ``X`` memberships are exactly
the data the strategy needs.

Cost: each closure is linear in the game size; each persistence step is
linear in the part of the game still outside ``Y``.  Random games with
10^5 positions / 10^6 moves take a fraction of a second.  The worst case
(games that need a persistence step for every few positions of a long
chain) is quadratic, as for the textbook algorithm.

Strategy
--------
:class:`GR1Strategy` is the usual counter strategy, tabulated.  Its memory is
the index ``j`` of the guarantee currently pursued (``n_memory`` equals the
number of guarantees; the initial memory is ``0``).  For memory ``j`` at a
position ``v`` of ``Y``-rank ``r`` (for goal ``j``) and every environment
choice ``c`` the table stores the system's answer:

* ``v`` in ``J^s_j & cpre(Z)`` (goal ``j`` is being visited *now*): move into
  ``Z`` (preferring a low rank for goal ``j+1``) and set the memory to
  ``(j + 1) mod n``.  The memory is thus updated in the step that *leaves*
  a reached ``J^s_j`` position: the memory stored with a position is the goal
  that is still pending there;
* ``v`` entered ``Y`` through ``cpre`` of the positions of rank ``< r``:
  move to a position of rank ``< r`` (memory unchanged);
* otherwise ``v`` entered in a persistence step and lies in
  ``!J^e_i & cpre(X_i)`` for the smallest such ``i``: move to a position of
  rank ``< r`` or of rank ``r`` inside ``X_i`` (lower ranks preferred;
  memory unchanged).

With fixed memory the rank never increases and, within a rank, the index
``i`` never increases, so a play that stops cycling through the goals ends
up staying in some ``!J^e_i`` forever, i.e. it violates an assumption.
:func:`verify_strategy` checks winning-ness independently by model checking
the closed loop.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

__all__ = [
    "GR1Game",
    "GR1Result",
    "GR1Strategy",
    "StrategyError",
    "solve",
    "verify_strategy",
]

_INF_RANK = np.iinfo(np.int32).max
_KIND_GOAL = 0
_KIND_PRE = 1
_KIND_PERSIST = 2
_FORMAT = "flowtest.gr1.strategy"
_FORMAT_VERSION = 1


class StrategyError(AssertionError):
    """Raised by :func:`verify_strategy` when a strategy is not winning.

    It derives from :class:`AssertionError` so that test code can treat a
    failed verification like a failed assertion.
    """


# ---------------------------------------------------------------------------
# input normalisation helpers
# ---------------------------------------------------------------------------


def _as_index_array(value: Any, name: str, upper: int | None) -> np.ndarray:
    """Return ``value`` as a read-only 1-D int64 array of indices.

    Parameters
    ----------
    value
        Array-like of integers.
    name
        Field name used in error messages.
    upper
        If given, every entry must lie in ``[0, upper)``.

    Returns
    -------
    numpy.ndarray
        A fresh, read-only int64 array.

    Raises
    ------
    ValueError
        If ``value`` is not a 1-D integer array or has out-of-range entries.
    """
    arr = np.asarray(value)
    if arr.size == 0:
        arr = arr.reshape(-1).astype(np.int64)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be one-dimensional, got shape {arr.shape}")
    if arr.dtype == np.bool_ or not np.issubdtype(arr.dtype, np.integer):
        raise ValueError(f"{name} must contain integers, got dtype {arr.dtype}")
    arr = arr.astype(np.int64, copy=True)
    if upper is not None and arr.size:
        bad = np.flatnonzero((arr < 0) | (arr >= upper))
        if bad.size:
            k = int(bad[0])
            raise ValueError(
                f"{name}[{k}] = {int(arr[k])} is out of range [0, {upper})"
            )
    arr.flags.writeable = False
    return arr


def _as_mask(value: Any, name: str, n: int) -> np.ndarray:
    """Return ``value`` as a read-only boolean mask of length ``n``.

    Raises
    ------
    ValueError
        If ``value`` is not a boolean array of shape ``(n,)``.
    """
    arr = np.asarray(value)
    if arr.dtype != np.bool_:
        raise ValueError(
            f"{name} must be a boolean mask over positions, got dtype {arr.dtype}"
        )
    if arr.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},), got {arr.shape}")
    arr = arr.copy()
    arr.flags.writeable = False
    return arr


def _set_to_mask(value: Any, name: str, n: int) -> np.ndarray:
    """Convert a position set (iterable of indices or bool mask) to a mask.

    Raises
    ------
    ValueError
        If an index is out of range or a mask has the wrong length.
    """
    if isinstance(value, np.ndarray) and value.dtype == np.bool_:
        return _as_mask(value, name, n)
    idx = _as_index_array(list(value), name, n)
    mask = np.zeros(n, dtype=bool)
    mask[idx] = True
    return mask


# ---------------------------------------------------------------------------
# game
# ---------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class GR1Game:
    """An explicit alternating GR(1) game (see the module docstring).

    Parameters
    ----------
    n_positions
        Number of positions; positions are ``0 .. n_positions - 1``.  At a
        position the environment chooses next.
    choice_owner
        ``int`` array ``[n_choices]``: the position at which each environment
        choice is available.
    choice_succ_ptr
        CSR pointer ``[n_choices + 1]`` into ``choice_succ``.
    choice_succ
        ``int`` array: the positions the system may move to after each
        choice (choice ``c`` owns ``choice_succ[ptr[c]:ptr[c + 1]]``).
    initial
        Initial groups (``int`` arrays of positions).  For every group
        (picked by the environment) the system must be able to pick a
        winning position inside it.
    env_liveness
        Boolean masks ``J^e_i`` over positions (assumptions ``GF J^e_i``).
    sys_liveness
        Boolean masks ``J^s_j`` over positions (guarantees ``GF J^s_j``); an
        empty list stands for the single guarantee ``GF true``.

    Raises
    ------
    ValueError
        If the arrays are inconsistent (bad shapes, dtypes or indices).

    Notes
    -----
    The arrays are copied and made read-only on construction, so a game is
    immutable and can be shared safely.  Use :meth:`from_lists` to build a
    game from plain Python containers.
    """

    n_positions: int
    choice_owner: np.ndarray
    choice_succ_ptr: np.ndarray
    choice_succ: np.ndarray
    initial: list[np.ndarray]
    env_liveness: list[np.ndarray]
    sys_liveness: list[np.ndarray]

    def __post_init__(self) -> None:
        """Validate and normalise all fields (called by the dataclass)."""
        n = self.n_positions
        if isinstance(n, (bool, np.bool_)) or not isinstance(n, (int, np.integer)):
            raise ValueError(f"n_positions must be an int, got {n!r}")
        n = int(n)
        if n < 0:
            raise ValueError(f"n_positions must be >= 0, got {n}")
        owner = _as_index_array(self.choice_owner, "choice_owner", n)
        succ = _as_index_array(self.choice_succ, "choice_succ", n)
        ptr = _as_index_array(self.choice_succ_ptr, "choice_succ_ptr", None)
        m = owner.size
        if ptr.size != m + 1:
            raise ValueError(
                f"choice_succ_ptr must have n_choices + 1 = {m + 1} entries, "
                f"got {ptr.size}"
            )
        if ptr[0] != 0:
            raise ValueError(f"choice_succ_ptr[0] must be 0, got {int(ptr[0])}")
        if np.any(np.diff(ptr) < 0):
            raise ValueError("choice_succ_ptr must be non-decreasing")
        if ptr[-1] != succ.size:
            raise ValueError(
                f"choice_succ_ptr[-1] = {int(ptr[-1])} must equal "
                f"len(choice_succ) = {succ.size}"
            )
        for field_name in ("initial", "env_liveness", "sys_liveness"):
            if isinstance(getattr(self, field_name), (np.ndarray, str, bytes)):
                raise ValueError(f"{field_name} must be a list of arrays")
        initial = [
            _as_index_array(g, f"initial[{k}]", n) for k, g in enumerate(self.initial)
        ]
        env = [
            _as_mask(s, f"env_liveness[{k}]", n)
            for k, s in enumerate(self.env_liveness)
        ]
        sys_ = [
            _as_mask(s, f"sys_liveness[{k}]", n)
            for k, s in enumerate(self.sys_liveness)
        ]
        object.__setattr__(self, "n_positions", n)
        object.__setattr__(self, "choice_owner", owner)
        object.__setattr__(self, "choice_succ_ptr", ptr)
        object.__setattr__(self, "choice_succ", succ)
        object.__setattr__(self, "initial", initial)
        object.__setattr__(self, "env_liveness", env)
        object.__setattr__(self, "sys_liveness", sys_)

    @property
    def n_choices(self) -> int:
        """Number of environment choices (over all positions)."""
        return int(self.choice_owner.size)

    @property
    def n_edges(self) -> int:
        """Number of system moves (entries of ``choice_succ``)."""
        return int(self.choice_succ.size)

    def successors(self, choice: int) -> np.ndarray:
        """Return the positions the system may move to after ``choice``."""
        return self.choice_succ[self.choice_succ_ptr[choice] : self.choice_succ_ptr[choice + 1]]

    @classmethod
    def from_lists(
        cls,
        n_positions: int,
        choices: Sequence[tuple[int, Iterable[int]]],
        initial: Iterable[Iterable[int]],
        env_liveness: Iterable[Iterable[int] | np.ndarray] = (),
        sys_liveness: Iterable[Iterable[int] | np.ndarray] = (),
    ) -> GR1Game:
        """Build a game from plain Python containers.

        Parameters
        ----------
        n_positions
            Number of positions.
        choices
            One ``(owner_position, successor_positions)`` pair per environment
            choice; the choice index is the index in this sequence.
        initial
            Initial groups, each an iterable of positions.
        env_liveness, sys_liveness
            Liveness sets, each given either as an iterable of positions or as
            a boolean numpy mask of length ``n_positions``.

        Returns
        -------
        GR1Game
            The validated game.

        Raises
        ------
        ValueError
            If a choice is malformed or any index is out of range.
        """
        if isinstance(n_positions, bool) or not isinstance(n_positions, (int, np.integer)):
            raise ValueError(f"n_positions must be an int, got {n_positions!r}")
        n = int(n_positions)
        if n < 0:
            raise ValueError(f"n_positions must be >= 0, got {n}")
        owners: list[int] = []
        ptr: list[int] = [0]
        succ: list[int] = []
        for k, item in enumerate(choices):
            try:
                owner, targets = item
            except (TypeError, ValueError):
                raise ValueError(
                    f"choices[{k}] must be a pair (owner, successors), got {item!r}"
                ) from None
            if isinstance(owner, bool) or not isinstance(owner, (int, np.integer)):
                raise ValueError(f"choices[{k}]: owner must be an int, got {owner!r}")
            if not 0 <= int(owner) < n:
                raise ValueError(
                    f"choices[{k}]: owner {int(owner)} is out of range [0, {n})"
                )
            tlist = [int(t) for t in targets]
            for t in tlist:
                if not 0 <= t < n:
                    raise ValueError(
                        f"choices[{k}]: successor {t} is out of range [0, {n})"
                    )
            owners.append(int(owner))
            succ.extend(tlist)
            ptr.append(len(succ))
        groups = [
            _as_index_array([int(p) for p in g], f"initial[{k}]", n)
            for k, g in enumerate(initial)
        ]
        env = [_set_to_mask(s, f"env_liveness[{k}]", n) for k, s in enumerate(env_liveness)]
        sys_ = [_set_to_mask(s, f"sys_liveness[{k}]", n) for k, s in enumerate(sys_liveness)]
        return cls(
            n_positions=n,
            choice_owner=np.asarray(owners, dtype=np.int64),
            choice_succ_ptr=np.asarray(ptr, dtype=np.int64),
            choice_succ=np.asarray(succ, dtype=np.int64),
            initial=groups,
            env_liveness=env,
            sys_liveness=sys_,
        )


# ---------------------------------------------------------------------------
# precomputed index structures and vectorised primitives
# ---------------------------------------------------------------------------


def _gather_ranges(ptr: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """Return the concatenation of ``arange(ptr[v], ptr[v + 1])`` over ``nodes``.

    This is the vectorised "expand CSR rows" primitive; its cost is linear in
    the number of returned indices (plus ``len(nodes)``).
    """
    starts = ptr[nodes]
    lens = ptr[nodes + 1] - starts
    total = int(lens.sum())
    if total == 0:
        return np.empty(0, dtype=np.int64)
    offsets = np.cumsum(lens) - lens
    return np.repeat(starts - offsets, lens) + np.arange(total, dtype=np.int64)


class _GameIndex:
    """CSR/reverse-CSR views of a game shared by all fixpoint computations.

    Attributes
    ----------
    n, m, n_edges
        Numbers of positions, choices and system moves.
    owner, ptr, succ
        The game's arrays.
    edge_choice
        For every move (entry of ``succ``) the choice it belongs to.
    outdeg
        Number of successors of every choice.
    choices_per_pos, pos_ptr, pos_choices
        CSR from positions to the choices they own.
    rev_ptr, rev_choice
        Reverse CSR: for a position ``u``, ``rev_choice[rev_ptr[u]:rev_ptr[u+1]]``
        lists the choice of every move into ``u`` (with multiplicity).
    matrix
        ``scipy.sparse`` CSR matrix ``[n_choices, n_positions]`` counting the
        moves of each choice into each position (for "how many successors in
        S" as one sparse matrix-vector product).
    """

    def __init__(self, game: GR1Game) -> None:
        self.n = game.n_positions
        self.m = game.n_choices
        self.n_edges = game.n_edges
        self.owner = game.choice_owner
        self.ptr = game.choice_succ_ptr
        self.succ = game.choice_succ
        self.outdeg = np.diff(self.ptr)
        self.edge_choice = np.repeat(np.arange(self.m, dtype=np.int64), self.outdeg)
        self.choices_per_pos = np.bincount(self.owner, minlength=self.n).astype(np.int64)
        self.pos_ptr = np.zeros(self.n + 1, dtype=np.int64)
        np.cumsum(self.choices_per_pos, out=self.pos_ptr[1:])
        self.pos_choices = np.argsort(self.owner, kind="stable")
        order = np.argsort(self.succ, kind="stable")
        self.rev_choice = self.edge_choice[order]
        self.rev_ptr = np.zeros(self.n + 1, dtype=np.int64)
        np.cumsum(np.bincount(self.succ, minlength=self.n), out=self.rev_ptr[1:])
        self.matrix = sp.csr_matrix(
            (np.ones(self.n_edges, dtype=np.int32), self.succ, self.ptr),
            shape=(self.m, self.n),
        )
        # scratch buffers (their contents are never assumed between calls)
        self._stamp = np.zeros(max(self.n, self.m), dtype=np.int64)
        self._remaining = np.zeros(self.m, dtype=np.int64)

    def unique(self, items: np.ndarray) -> np.ndarray:
        """Remove duplicates from an array of position/choice ids in O(len).

        Keeps the last occurrence of each id (order otherwise preserved);
        avoids the sort of :func:`numpy.unique` in hot frontier loops.
        """
        if items.size <= 1:
            return items
        k = np.arange(items.size)
        self._stamp[items] = k
        out: np.ndarray = items[self._stamp[items] == k]
        return out

    def count_in(self, target: np.ndarray) -> np.ndarray:
        """Return, for every choice, its number of successors in ``target``."""
        out: np.ndarray = self.matrix @ target.view(np.int8)
        return out

    def cpre(self, target: np.ndarray) -> np.ndarray:
        """Controllable predecessor of a position set.

        Parameters
        ----------
        target
            Boolean mask over positions.

        Returns
        -------
        numpy.ndarray
            Mask of positions where, for every environment choice, the system
            has a successor in ``target`` (positions without choices included).
        """
        failing = self.owner[self.count_in(target) == 0]
        out: np.ndarray = np.bincount(failing, minlength=self.n) == 0
        return out

    def persist_or_reach(
        self, reach: np.ndarray, live: np.ndarray, domain: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Compute ``X = nu X. reach | (!live & cpre(X))`` and its complement.

        ``X`` is the set from which the system can keep the play in ``!live``
        forever unless it reaches ``reach``.  Its complement ``W`` is the
        environment attractor of ``live & !reach`` inside ``!reach``; it is
        computed with per-choice counters of successors outside ``W``,
        processed frontier by frontier, so the cost is linear in the size of
        the explored part of the game.

        Parameters
        ----------
        reach
            Mask of positions that count as "done".
        live
            Mask of the assumption set ``J^e_i``.
        domain
            Optional mask known to contain ``W`` (e.g. the complement computed
            for a smaller ``reach``; ``W`` shrinks when ``reach`` grows).  Only
            choices owned by ``domain`` positions are initialised, which makes
            repeated calls with growing ``reach`` cheap.

        Returns
        -------
        tuple[numpy.ndarray, numpy.ndarray]
            Boolean masks ``(X, W)`` with ``W = ~X``.
        """
        inside = ~reach if domain is None else domain & ~reach
        lost = inside & live
        remaining = self._remaining
        dpos = np.flatnonzero(inside)
        if 4 * dpos.size >= self.n:
            remaining[:] = self.outdeg - self.count_in(lost)
            forced = np.flatnonzero(remaining == 0)
        else:
            ch = self.pos_choices[_gather_ranges(self.pos_ptr, dpos)]
            edges = _gather_ranges(self.ptr, ch)
            local = np.repeat(np.arange(ch.size), self.outdeg[ch])
            hits = np.bincount(local[lost[self.succ[edges]]], minlength=ch.size)
            remaining[ch] = self.outdeg[ch] - hits
            forced = ch[remaining[ch] == 0]
        cand = self.owner[forced]
        cand = self.unique(cand[inside[cand] & ~lost[cand]])
        lost[cand] = True
        frontier = cand
        while frontier.size:
            ch = self.rev_choice[_gather_ranges(self.rev_ptr, frontier)]
            if ch.size == 0:
                break
            np.subtract.at(remaining, ch, 1)
            # choices owned outside ``inside`` may hold stale counts; their
            # owners are filtered out below, so they are harmless
            ch = ch[remaining[ch] == 0]
            cand = self.owner[ch]
            cand = self.unique(cand[inside[cand] & ~lost[cand]])
            lost[cand] = True
            frontier = cand
        return ~lost, lost


class _CpreCounter:
    """Incrementally maintained ``cpre(Y)`` for a growing set ``Y``.

    ``hit[c]`` counts the successors of choice ``c`` inside ``Y`` and
    ``bad[v]`` the choices of ``v`` without such a successor; ``v`` is in
    ``cpre(Y)`` iff ``bad[v] == 0``.  Adding positions costs time linear in
    the number of moves into them.
    """

    def __init__(self, ix: _GameIndex) -> None:
        self.ix = ix
        self.hit = np.zeros(ix.m, dtype=np.int64)
        self.bad = ix.choices_per_pos.copy()
        self.mask = self.bad == 0

    def add(self, nodes: np.ndarray) -> np.ndarray:
        """Add ``nodes`` (distinct, not yet in ``Y``) to ``Y``.

        Returns
        -------
        numpy.ndarray
            Positions that have newly entered ``cpre(Y)`` (distinct).
        """
        ix = self.ix
        ch = ix.rev_choice[_gather_ranges(ix.rev_ptr, nodes)]
        if ch.size == 0:
            return np.empty(0, dtype=np.int64)
        newly_ok = ix.unique(ch[self.hit[ch] == 0])
        np.add.at(self.hit, ch, 1)
        if newly_ok.size == 0:
            return np.empty(0, dtype=np.int64)
        pos = ix.owner[newly_ok]
        np.subtract.at(self.bad, pos, 1)
        entered = ix.unique(pos[self.bad[pos] == 0])
        self.mask[entered] = True
        return entered


@dataclass
class _Basin:
    """Iteration data of ``mu Y`` for one guarantee (internal).

    Attributes
    ----------
    inside
        Mask of ``Y`` (the positions from which goal ``j`` is forced).
    rank
        Batch (closure layer or persistence step) in which each position
        entered ``Y``, counting from 1 (``_INF_RANK`` if never).
    kind
        ``_KIND_GOAL`` / ``_KIND_PRE`` / ``_KIND_PERSIST``: why it entered.
    persist
        For ``_KIND_PERSIST`` positions the smallest ``i`` with ``v`` in the
        ``X_i`` of its persistence step (else ``-1``).
    member
        ``member[v, i]``: ``v`` is in ``X_i`` of its own persistence step.
    """

    inside: np.ndarray
    rank: np.ndarray
    kind: np.ndarray
    persist: np.ndarray
    member: np.ndarray


def _basin(ix: _GameIndex, goal: np.ndarray, env: list[np.ndarray]) -> _Basin:
    """Evaluate ``mu Y. OR_i nu X. goal | cpre(Y) | (!J^e_i & cpre(X))``.

    The least fixpoint is reached by alternating two kinds of steps, each of
    which only adds positions that belong to it:

    * *closure*: the system attractor of ``Y`` (``Y := Y | cpre(Y)`` until
      stable) layer by layer with incremental counters -- linear time overall;
    * *persistence*: once ``Y`` is closed (so ``goal | cpre(Y) == Y``), add
      ``OR_i nu X. Y | (!J^e_i & cpre(X))`` (one environment attractor per
      assumption, restricted to what the previous round left outside).

    When neither step adds anything, ``Y`` is a fixpoint of the operator and,
    being built from below, the least one.  Every batch of added positions
    gets the next rank, which yields the well-founded progress measure used
    by the strategy: a "pre" position has all answers in lower ranks, a
    "persist" position of rank ``r`` (for assumption ``i``) can stay in
    ``!J^e_i`` positions of rank ``r`` that are in ``X_i`` or go lower.
    Compared to the textbook stage-by-stage iteration this needs far fewer
    (expensive) ``nu X`` computations on games with long attractor chains.

    Parameters
    ----------
    ix
        Game index.
    goal
        Mask ``J^s_j & cpre(Z)``.
    env
        Assumption masks ``J^e_i`` (an empty list means no assumption, in which
        case the iteration is a plain attractor computation).

    Returns
    -------
    _Basin
        The ``Y`` set with ranks and ``X`` memberships for strategy extraction.
    """
    n = ix.n
    n_env = len(env)
    inside = np.zeros(n, dtype=bool)
    rank = np.full(n, _INF_RANK, dtype=np.int32)
    kind = np.full(n, _KIND_PRE, dtype=np.int8)
    persist = np.full(n, -1, dtype=np.int32)
    member = np.zeros((n, n_env), dtype=bool)
    counter = _CpreCounter(ix)
    # complements of the X_i of the previous persistence step: they only
    # shrink as Y grows, so each step re-examines only them
    domains: list[np.ndarray | None] = [None] * n_env
    next_rank = 1
    new = np.flatnonzero(goal | counter.mask)  # cpre(empty) = env-stuck positions
    kind[new] = np.where(goal[new], _KIND_GOAL, _KIND_PRE)
    while True:
        # closure: attractor layering, one rank per layer
        while new.size:
            rank[new] = next_rank
            next_rank += 1
            inside[new] = True
            entered = counter.add(new)
            new = entered[~inside[entered]]
            kind[new] = _KIND_PRE
        if n_env == 0:
            break
        # persistence step with reach = Y (closed: goal | cpre(Y) == Y)
        xs = []
        for i, live in enumerate(env):
            x, domains[i] = ix.persist_or_reach(inside, live, domains[i])
            xs.append(x)
        grown = xs[0].copy()
        for x in xs[1:]:
            grown |= x
        new = np.flatnonzero(grown & ~inside)
        if new.size == 0:
            break
        kind[new] = _KIND_PERSIST
        mem = np.stack([x[new] for x in xs], axis=1)
        member[new] = mem
        persist[new] = np.argmax(mem, axis=1)
    return _Basin(inside, rank, kind, persist, member)


# ---------------------------------------------------------------------------
# strategy
# ---------------------------------------------------------------------------


@dataclass
class GR1Strategy:
    """A tabulated finite-memory strategy for the system.

    Parameters
    ----------
    n_positions
        Number of positions of the game the strategy was built for.
    initial
        ``int32`` array ``[n_groups]``: the system's pick in each initial group.
    next_position
        ``int32`` array ``[n_memory, n_choices]``: the successor chosen for
        each (memory, environment choice); ``-1`` where no move is defined
        (the position is losing or the entry is unreachable).
    next_memory
        ``int32`` array ``[n_memory, n_choices]``: the memory after that move
        (``-1`` where ``next_position`` is ``-1``).

    Notes
    -----
    The memory is the index of the guarantee currently pursued; the initial
    memory is :attr:`initial_memory` (``0``).  The memory changes from ``j``
    to ``(j + 1) mod n_memory`` exactly in the move that leaves a position of
    ``J^s_j`` reached while pursuing ``j`` (see the module docstring).  A
    run is executed as::

        pos, mem = strategy.initial_choice(g), strategy.initial_memory
        while True:
            c = <environment picks a choice owned by pos>
            pos, mem = strategy.move(mem, c)
    """

    n_positions: int
    initial: np.ndarray
    next_position: np.ndarray
    next_memory: np.ndarray

    initial_memory: int = 0

    def __post_init__(self) -> None:
        """Validate table shapes and value ranges.

        Raises
        ------
        ValueError
            If the arrays are inconsistent.
        """
        self.n_positions = int(self.n_positions)
        self.initial = np.asarray(self.initial, dtype=np.int32).reshape(-1)
        self.next_position = np.asarray(self.next_position, dtype=np.int32)
        self.next_memory = np.asarray(self.next_memory, dtype=np.int32)
        if self.next_position.ndim != 2 or self.next_position.shape != self.next_memory.shape:
            raise ValueError(
                "next_position and next_memory must be 2-D arrays of equal shape, "
                f"got {self.next_position.shape} and {self.next_memory.shape}"
            )
        if self.next_position.shape[0] < 1:
            raise ValueError("a strategy needs at least one memory value")
        if np.any(self.initial < 0) or np.any(self.initial >= self.n_positions):
            raise ValueError("initial positions out of range")
        if np.any(self.next_position < -1) or np.any(self.next_position >= self.n_positions):
            raise ValueError("next_position entries out of range")
        if np.any(self.next_memory < -1) or np.any(self.next_memory >= self.n_memory):
            raise ValueError("next_memory entries out of range")
        if np.any((self.next_position < 0) != (self.next_memory < 0)):
            raise ValueError("next_position and next_memory must be -1 at the same entries")
        if not 0 <= self.initial_memory < self.n_memory:
            raise ValueError("initial_memory out of range")

    @property
    def n_memory(self) -> int:
        """Number of memory values (= number of guarantees)."""
        return int(self.next_position.shape[0])

    @property
    def n_choices(self) -> int:
        """Number of environment choices of the game."""
        return int(self.next_position.shape[1])

    @property
    def table(self) -> dict[str, np.ndarray]:
        """The move table as ``{"next_position": ..., "next_memory": ...}``."""
        return {"next_position": self.next_position, "next_memory": self.next_memory}

    def initial_positions(self) -> np.ndarray:
        """Return the system's pick for every initial group (a copy)."""
        return self.initial.copy()

    def initial_choice(self, group_index: int) -> int:
        """Return the system's (winning) pick in initial group ``group_index``."""
        return int(self.initial[group_index])

    def move(self, memory: int, choice: int) -> tuple[int, int]:
        """Answer an environment choice.

        Parameters
        ----------
        memory
            Current memory value.
        choice
            The environment's choice (owned by the current position).

        Returns
        -------
        tuple[int, int]
            ``(next_position, next_memory)``.

        Raises
        ------
        ValueError
            If the table has no move for this pair (losing or unreachable).
        """
        pos = int(self.next_position[memory, choice])
        if pos < 0:
            raise ValueError(f"no move defined for memory {memory}, choice {choice}")
        return pos, int(self.next_memory[memory, choice])

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-serialisable representation (plain lists and ints)."""
        return {
            "format": _FORMAT,
            "version": _FORMAT_VERSION,
            "n_positions": self.n_positions,
            "n_memory": self.n_memory,
            "n_choices": self.n_choices,
            "initial_memory": int(self.initial_memory),
            "initial": self.initial.tolist(),
            "next_position": self.next_position.tolist(),
            "next_memory": self.next_memory.tolist(),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> GR1Strategy:
        """Rebuild a strategy written by :meth:`to_dict`.

        Raises
        ------
        ValueError
            If the format tag, version or table shapes do not match.
        """
        if data.get("format") != _FORMAT or data.get("version") != _FORMAT_VERSION:
            raise ValueError(
                f"not a {_FORMAT} v{_FORMAT_VERSION} document: "
                f"format={data.get('format')!r}, version={data.get('version')!r}"
            )
        shape = (int(data["n_memory"]), int(data["n_choices"]))
        nxt = np.asarray(data["next_position"], dtype=np.int32).reshape(shape)
        mem = np.asarray(data["next_memory"], dtype=np.int32).reshape(shape)
        return cls(
            n_positions=int(data["n_positions"]),
            initial=np.asarray(data["initial"], dtype=np.int32),
            next_position=nxt,
            next_memory=mem,
            initial_memory=int(data["initial_memory"]),
        )


@dataclass
class GR1Result:
    """Outcome of :func:`solve`.

    Attributes
    ----------
    realizable
        Whether the system wins from the initial condition.
    winning
        Boolean mask of the winning region ``Z``.
    strategy
        A winning strategy if realizable, else ``None``.
    """

    realizable: bool
    winning: np.ndarray
    strategy: GR1Strategy | None


def _segment_argmin(key: np.ndarray, ptr: np.ndarray, sentinel: int) -> np.ndarray:
    """Per-CSR-segment minimum of ``key``; ``sentinel`` for empty segments."""
    m = ptr.size - 1
    out = np.full(m, sentinel, dtype=np.int64)
    nonempty = np.flatnonzero(ptr[1:] > ptr[:-1])
    if nonempty.size:
        out[nonempty] = np.minimum.reduceat(key, ptr[nonempty])
    return out


def _build_strategy(
    game: GR1Game, ix: _GameIndex, winning: np.ndarray, basins: list[_Basin]
) -> GR1Strategy:
    """Tabulate the counter strategy from the final fixpoint data.

    Raises
    ------
    RuntimeError
        If some position inside a basin has no admissible move (this would
        indicate a bug in the fixpoint computation).
    """
    n_mem = len(basins)
    E = ix.n_edges
    next_position = np.full((n_mem, ix.m), -1, dtype=np.int32)
    next_memory = np.full((n_mem, ix.m), -1, dtype=np.int32)
    succ = ix.succ
    edge_owner = ix.owner[ix.edge_choice]
    edge_id = np.arange(E, dtype=np.int64)
    sentinel = np.iinfo(np.int64).max
    for j, b in enumerate(basins):
        nxt_b = basins[(j + 1) % n_mem]
        r_v = b.rank[edge_owner].astype(np.int64)
        r_u = b.rank[succ].astype(np.int64)
        k_v = b.kind[edge_owner]
        valid = r_u < r_v
        is_goal = k_v == _KIND_GOAL
        valid[is_goal] = winning[succ[is_goal]]
        if b.member.shape[1]:
            pers = np.flatnonzero(k_v == _KIND_PERSIST)
            same = (r_u[pers] == r_v[pers]) & b.member[succ[pers], b.persist[edge_owner[pers]]]
            valid[pers] |= same
        valid &= r_v < _INF_RANK
        score = np.where(is_goal, nxt_b.rank[succ].astype(np.int64), r_u)
        key = np.where(valid, score * (E + 1) + edge_id, sentinel)
        best = _segment_argmin(key, ix.ptr, sentinel)
        has = best != sentinel
        active = b.inside[ix.owner]
        if np.any(active & ~has):
            c = int(np.flatnonzero(active & ~has)[0])
            raise RuntimeError(
                f"internal error: no admissible move for goal {j}, choice {c}"
            )
        chosen = best[has] % (E + 1)
        next_position[j, has] = succ[chosen]
        goal_choice = b.kind[ix.owner] == _KIND_GOAL
        next_memory[j, has] = np.where(goal_choice[has], (j + 1) % n_mem, j)
    init = np.empty(len(game.initial), dtype=np.int32)
    rank0 = basins[0].rank
    for g, group in enumerate(game.initial):
        cand = group[winning[group]]
        init[g] = int(cand[np.argmin(rank0[cand])])
    return GR1Strategy(
        n_positions=game.n_positions,
        initial=init,
        next_position=next_position,
        next_memory=next_memory,
    )


def solve(game: GR1Game) -> GR1Result:
    """Solve a GR(1) game.

    Parameters
    ----------
    game
        The game to solve.

    Returns
    -------
    GR1Result
        The verdict for the initial condition, the winning region and, if
        realizable, a winning strategy (initial memory ``0``).

    Notes
    -----
    The outer ``nu Z`` is evaluated Gauss-Seidel style (``Z := Z & Y_j(Z)``
    for each ``j`` in turn) until a full pass leaves ``Z`` unchanged; the
    ``Y`` data of that last pass, all computed with the final ``Z``, define
    the strategy.  Environment assumption sets equal to all positions are
    trivially satisfied and dropped; duplicates are merged.
    """
    ix = _GameIndex(game)
    n = ix.n
    env: list[np.ndarray] = []
    for live in game.env_liveness:
        if live.all() or any(np.array_equal(live, e) for e in env):
            continue
        env.append(live)
    goals = list(game.sys_liveness) or [np.ones(n, dtype=bool)]
    winning = np.ones(n, dtype=bool)
    while True:
        changed = False
        basins: list[_Basin] = []
        for goal_set in goals:
            target = goal_set & ix.cpre(winning)
            b = _basin(ix, target, env)
            shrunk = winning & b.inside
            if np.count_nonzero(shrunk) != np.count_nonzero(winning):
                winning = shrunk
                changed = True
            basins.append(b)
        if not changed:
            break
    realizable = all(bool(np.any(winning[g])) for g in game.initial)
    strategy = _build_strategy(game, ix, winning, basins) if realizable else None
    return GR1Result(realizable=realizable, winning=winning, strategy=strategy)


# ---------------------------------------------------------------------------
# verification
# ---------------------------------------------------------------------------


def verify_strategy(game: GR1Game, strategy: GR1Strategy) -> None:
    """Check that ``strategy`` wins ``game``; raise :class:`StrategyError` if not.

    The check uses only the game and the strategy table (no solver data):

    1. every initial pick lies in its group;
    2. the closed loop over states ``(position, memory)`` reachable from
       ``(pick, initial_memory)`` is explored under all environment choices;
       every reached (memory, choice) must have a move into the choice's
       successor list with a valid memory value;
    3. for each guarantee ``j``, the closed loop with the states at
       ``J^s_j`` positions removed is decomposed into strongly connected
       components; a component with an internal edge that meets every
       ``J^e_i`` is a reachable cycle satisfying all assumptions but visiting
       ``J^s_j`` finitely often, i.e. a counterexample.

    Parameters
    ----------
    game
        The game.
    strategy
        The strategy to check.

    Raises
    ------
    StrategyError
        With a description of the first violation found.
    """
    n, m = game.n_positions, game.n_choices
    n_mem = strategy.n_memory
    if strategy.n_positions != n or strategy.n_choices != m:
        raise StrategyError(
            f"strategy is for {strategy.n_positions} positions / {strategy.n_choices} "
            f"choices, game has {n} / {m}"
        )
    if strategy.initial.size != len(game.initial):
        raise StrategyError(
            f"strategy has {strategy.initial.size} initial picks, "
            f"game has {len(game.initial)} groups"
        )
    for g, group in enumerate(game.initial):
        pick = int(strategy.initial[g])
        if pick not in set(group.tolist()):
            raise StrategyError(f"initial pick {pick} is not in initial group {g}")
    owner = game.choice_owner
    order = np.argsort(owner, kind="stable")
    cptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(owner, minlength=n), out=cptr[1:])
    edge_choice = np.repeat(np.arange(m, dtype=np.int64), np.diff(game.choice_succ_ptr))
    legal = np.unique(edge_choice * max(n, 1) + game.choice_succ)
    visited = np.zeros(n * n_mem, dtype=bool)
    start = np.unique(strategy.initial.astype(np.int64) * n_mem + strategy.initial_memory)
    visited[start] = True
    frontier = start
    srcs: list[np.ndarray] = []
    dsts: list[np.ndarray] = []
    while frontier.size:
        pos = frontier // n_mem
        idx = _gather_ranges(cptr, pos)
        counts = cptr[pos + 1] - cptr[pos]
        src = np.repeat(frontier, counts)
        c = order[idx]
        mem = src % n_mem
        nxt = strategy.next_position[mem, c].astype(np.int64)
        nmem = strategy.next_memory[mem, c].astype(np.int64)
        bad = np.flatnonzero((nxt < 0) | (nmem < 0) | (nmem >= n_mem))
        if bad.size:
            k = int(bad[0])
            raise StrategyError(
                f"no valid move at position {int(src[k] // n_mem)}, memory "
                f"{int(mem[k])}, environment choice {int(c[k])}"
            )
        keys = c * max(n, 1) + nxt
        where = np.searchsorted(legal, keys)
        ok = where < legal.size
        ok[ok] = legal[where[ok]] == keys[ok]
        if not ok.all():
            k = int(np.flatnonzero(~ok)[0])
            raise StrategyError(
                f"illegal move to position {int(nxt[k])} after environment choice "
                f"{int(c[k])} (memory {int(mem[k])})"
            )
        dst = nxt * n_mem + nmem
        srcs.append(src)
        dsts.append(dst)
        new = np.unique(dst[~visited[dst]])
        visited[new] = True
        frontier = new
    states = np.flatnonzero(visited)
    n_states = states.size
    if n_states == 0:
        return
    src = np.concatenate(srcs) if srcs else np.empty(0, dtype=np.int64)
    dst = np.concatenate(dsts) if dsts else np.empty(0, dtype=np.int64)
    s_idx = np.searchsorted(states, src)
    d_idx = np.searchsorted(states, dst)
    state_pos = states // n_mem
    guarantees = list(game.sys_liveness) or [np.ones(n, dtype=bool)]
    for j, goal in enumerate(guarantees):
        keep = ~goal[state_pos]
        e_keep = keep[s_idx] & keep[d_idx]
        es, ed = s_idx[e_keep], d_idx[e_keep]
        if es.size == 0:
            continue
        graph = sp.csr_matrix(
            (np.ones(es.size, dtype=np.int8), (es, ed)), shape=(n_states, n_states)
        )
        n_comp, labels = connected_components(graph, directed=True, connection="strong")
        internal = labels[es] == labels[ed]
        nontrivial = np.zeros(n_comp, dtype=bool)
        nontrivial[labels[es[internal]]] = True
        bad_comp = nontrivial
        for live in game.env_liveness:
            hit = np.zeros(n_comp, dtype=bool)
            hit[labels[keep & live[state_pos]]] = True
            bad_comp = bad_comp & hit
        if bad_comp.any():
            comp = int(np.flatnonzero(bad_comp)[0])
            members = states[labels == comp]
            sample = [(int(s // n_mem), int(s % n_mem)) for s in members[:8]]
            raise StrategyError(
                f"guarantee {j} can be avoided forever while all assumptions hold: "
                f"reachable cycle through (position, memory) states {sample}"
                + (" ..." if members.size > 8 else "")
            )
