"""Stage 3 of the GR(1) solver (:mod:`synthesis.test_agent.gr1`): the inner least fixpoint
``mu Y`` of one guarantee (:func:`basin`), the positions from which the system forces a visit
to the goal or an assumption's violation, each with the rank of the batch it entered in and
why (:class:`Basin`): the data the strategy is read from."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .index import CpreCounter, GameIndex

INF_RANK = np.iinfo(np.int32).max
"""The rank of a position that never entered ``Y``."""
KIND_GOAL = 0
"""Why a position entered ``Y``: it is in the goal ``J^s_j & cpre(Z)``, ..."""
KIND_PRE = 1
"""... in ``cpre`` of the lower ranks (a closure step), ..."""
KIND_PERSIST = 2
"""... or in a persistence step (``!J^e_i & cpre(X_i)``)."""


@dataclass
class Basin:
    """Iteration data of ``mu Y`` for one guarantee (what the strategy is read from).

    Attributes
    ----------
    inside
        Mask of ``Y`` (the positions from which goal ``j`` is forced).
    rank
        Batch (closure layer or persistence step) in which each position
        entered ``Y``, counting from 1 (``INF_RANK`` if never).
    kind
        ``KIND_GOAL`` / ``KIND_PRE`` / ``KIND_PERSIST``: why it entered.
    persist
        For ``KIND_PERSIST`` positions the smallest ``i`` with ``v`` in the
        ``X_i`` of its persistence step (else ``-1``).
    member
        ``member[v, i]``: ``v`` is in ``X_i`` of its own persistence step.
    """

    inside: np.ndarray
    rank: np.ndarray
    kind: np.ndarray
    persist: np.ndarray
    member: np.ndarray


def basin(ix: GameIndex, goal: np.ndarray, env: list[np.ndarray]) -> Basin:
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
    Basin
        The ``Y`` set with ranks and ``X`` memberships for strategy extraction.
    """
    n = ix.n
    n_env = len(env)
    inside = np.zeros(n, dtype=bool)
    rank = np.full(n, INF_RANK, dtype=np.int32)
    kind = np.full(n, KIND_PRE, dtype=np.int8)
    persist = np.full(n, -1, dtype=np.int32)
    member = np.zeros((n, n_env), dtype=bool)
    counter = CpreCounter(ix)
    # complements of the X_i of the previous persistence step: they only
    # shrink as Y grows, so each step re-examines only them
    domains: list[np.ndarray | None] = [None] * n_env
    next_rank = 1
    new = np.flatnonzero(goal | counter.mask)  # cpre(empty) = env-stuck positions
    kind[new] = np.where(goal[new], KIND_GOAL, KIND_PRE)
    while True:
        # closure: attractor layering, one rank per layer
        while new.size:
            rank[new] = next_rank
            next_rank += 1
            inside[new] = True
            entered = counter.add(new)
            new = entered[~inside[entered]]
            kind[new] = KIND_PRE
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
        kind[new] = KIND_PERSIST
        mem = np.stack([x[new] for x in xs], axis=1)
        member[new] = mem
        persist[new] = np.argmax(mem, axis=1)
    return Basin(inside, rank, kind, persist, member)
