"""Stage 2 of the GR(1) solver (:mod:`synthesis.test_agent.gr1`): the game's CSR and
reverse-CSR views (:class:`GameIndex`), built once and shared by every fixpoint, and the
vectorised primitives they run on: the controllable predecessor ``cpre`` and the environment
attractor behind ``nu X`` (:meth:`GameIndex.cpre`, :meth:`GameIndex.persist_or_reach`), and
``cpre(Y)`` kept by counters for a growing ``Y`` (:class:`CpreCounter`). No fixpoint holds a
per-position Python loop: each step is a sparse product, a ``bincount`` or fancy indexing."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .game import GR1Game


def gather_ranges(ptr: np.ndarray, nodes: np.ndarray) -> np.ndarray:
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


class GameIndex:
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

    def persist_or_reach(self, reach: np.ndarray, live: np.ndarray, domain: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
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
            ch = self.pos_choices[gather_ranges(self.pos_ptr, dpos)]
            edges = gather_ranges(self.ptr, ch)
            local = np.repeat(np.arange(ch.size), self.outdeg[ch])
            hits = np.bincount(local[lost[self.succ[edges]]], minlength=ch.size)
            remaining[ch] = self.outdeg[ch] - hits
            forced = ch[remaining[ch] == 0]
        cand = self.owner[forced]
        cand = self.unique(cand[inside[cand] & ~lost[cand]])
        lost[cand] = True
        frontier = cand
        while frontier.size:
            ch = self.rev_choice[gather_ranges(self.rev_ptr, frontier)]
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


class CpreCounter:
    """Incrementally maintained ``cpre(Y)`` for a growing set ``Y``.

    ``hit[c]`` counts the successors of choice ``c`` inside ``Y`` and
    ``bad[v]`` the choices of ``v`` without such a successor; ``v`` is in
    ``cpre(Y)`` iff ``bad[v] == 0``.  Adding positions costs time linear in
    the number of moves into them.
    """

    def __init__(self, ix: GameIndex) -> None:
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
        ch = ix.rev_choice[gather_ranges(ix.rev_ptr, nodes)]
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
