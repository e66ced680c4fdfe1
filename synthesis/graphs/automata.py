"""Deterministic Büchi automata (DBA) of objectives, and the specification product B_pi.

Conventions (docs/method.md §3):

* An automaton reads the *label* of a state, i.e. the set of propositions true there.
  Its alphabet is the list of distinct labels that occur in the transition system at
  hand (``letters``), not all of ``2^AP``: only those letters are ever read, so the
  tables stay small and minimisation can merge more states without changing any
  product graph.
* Acceptance is state based. Executions are finite and read as stuttering forever
  on their last state; every pattern automaton is idempotent on a repeated letter,
  hence so is their product, and a finite execution satisfies a conjunction exactly
  when the automaton state after its last letter accepts in *every* part. The
  product therefore accepts where all parts accept.
* Automata are reduced by partition refinement (Moore): states that agree on
  acceptance and on the classes of their successors for every letter are merged.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ..model.errors import ProblemTooLarge
from ..model.specs import Formula, Objective, Task, holds, to_text

Label = frozenset[str]


@dataclass
class DBA:
    """A complete DBA over ``letters``.

    Attributes
    ----------
    delta
        ``int32[n_states, n_letters]``: successor of each state on each letter.
    initial
        The initial state ``q0`` (before any letter is read).
    accepting
        ``bool[n_states, n_sets]``: one column per acceptance set (one for an
        objective; two, system then test, for the specification product).
    letters
        The alphabet: labels as frozensets of proposition names.
    names
        A short human description of each state (its progress).
    components
        For a product, ``int32[n_states, n_parts]``: the state of each part.
    """

    delta: np.ndarray
    initial: int
    accepting: np.ndarray
    letters: tuple[Label, ...]
    names: list[str]
    components: np.ndarray | None = field(default=None)

    @property
    def n_states(self) -> int:
        return int(self.delta.shape[0])

    @property
    def n_transitions(self) -> int:
        """Distinct state pairs ``(q, q')`` linked by some letter."""
        q = np.repeat(np.arange(self.n_states), self.delta.shape[1])
        return int(np.unique(q * self.n_states + self.delta.ravel()).size)

    def letter_index(self, label: Label) -> int:
        return self.letters.index(label)

    def step(self, q: int, label: Label) -> int:
        return int(self.delta[q, self.letter_index(label)])


# -------------------------------------------------------------- pattern automata


def _truth(f: Formula, letters: Sequence[Label]) -> np.ndarray:
    return np.fromiter((holds(f, a) for a in letters), dtype=bool, count=len(letters))


def task_automaton(task: Task, letters: Sequence[Label]) -> DBA:
    """The DBA of one sub-task (docs/method.md §3)."""
    k = len(letters)
    truth = [_truth(p, letters) for p in task.props]
    if task.kind in ("visit", "sequenced"):
        m = len(truth)
        delta = np.empty((m + 1, k), dtype=np.int32)
        for i in range(m + 1):
            stage = np.full(k, i, dtype=np.int32)
            # advance greedily: several stages may complete on the same letter
            active = np.ones(k, dtype=bool)
            for j in range(i, m):
                active &= truth[j]
                stage[active] = j + 1
            delta[i] = stage
        accepting = np.zeros((m + 1, 1), dtype=bool)
        accepting[m] = True
        props = [to_text(p) for p in task.props]
        names = ["" if i == 0 else "saw " + " then ".join(props[:i]) for i in range(m + 1)]
        return DBA(delta, 0, accepting, tuple(letters), names)
    if task.kind in ("safety", "reaction"):
        ok = truth[0] if task.kind == "safety" else (~truth[0] | truth[1])
        delta = np.array([np.where(ok, 0, 1), np.ones(k)], dtype=np.int32)
        accepting = np.array([[True], [False]])
        return DBA(delta, 0, accepting, tuple(letters), ["", f"violated {task.text}"])
    if task.kind == "delayed":
        p, q = truth
        delta = np.array([np.where(p & ~q, 1, 0), np.where(q, 0, 1)], dtype=np.int32)
        accepting = np.array([[True], [False]])
        return DBA(delta, 0, accepting, tuple(letters), ["", f"pending {to_text(task.props[1])}"])
    raise ValueError(f"unknown task kind {task.kind!r}")


# ----------------------------------------------------------- product and reduction


def product(parts: Sequence[DBA], accept_all: bool = True, max_states: int | None = None) -> DBA:
    """Synchronous product of DBAs over the same letters, reachable part only.

    With ``accept_all`` the product has one acceptance column (every part accepts);
    otherwise it keeps one column per part (used for B_pi = B_sys x B_test).

    Raises
    ------
    ProblemTooLarge
        If the reachable part has more than ``max_states`` states (``None``: no bound).
    """
    letters = parts[0].letters
    k = len(letters)
    init = tuple(p.initial for p in parts)
    index: dict[tuple[int, ...], int] = {init: 0}
    order = [init]
    rows: list[np.ndarray] = []
    head = 0
    while head < len(order):
        state = order[head]
        head += 1
        succ = np.stack([p.delta[s] for p, s in zip(parts, state, strict=True)], axis=1)  # [k, n_parts]
        row = np.empty(k, dtype=np.int32)
        for a in range(k):
            t = tuple(int(x) for x in succ[a])
            j = index.get(t)
            if j is None:
                j = index[t] = len(order)
                order.append(t)
                if max_states is not None and len(order) > max_states:
                    raise ProblemTooLarge(f"the objectives' automaton has more than {max_states} states")
            row[a] = j
        rows.append(row)
    comps = np.array(order, dtype=np.int32).reshape(len(order), len(parts))
    acc = np.stack([p.accepting[comps[:, i], 0] for i, p in enumerate(parts)], axis=1)
    if accept_all:
        acc = np.asarray(acc.all(axis=1, keepdims=True))
    names = []
    for t in order:
        bits = [p.names[s] for p, s in zip(parts, t, strict=True) if p.names[s]]
        names.append("; ".join(bits))
    return DBA(np.array(rows, dtype=np.int32).reshape(len(order), k), 0, acc, letters, names, comps)


def minimize(dba: DBA) -> DBA:
    """Merge states that agree on acceptance and on successor classes (Moore)."""
    n = dba.n_states
    acc_key = dba.accepting.astype(np.int64) @ (1 << np.arange(dba.accepting.shape[1]))
    _, cls = np.unique(acc_key, return_inverse=True)
    n_cls = int(cls.max()) + 1 if n else 0
    while True:
        sig = np.concatenate([cls[:, None], cls[dba.delta]], axis=1)
        _, new = np.unique(sig, axis=0, return_inverse=True)
        new = new.ravel()
        n_new = int(new.max()) + 1
        if n_new == n_cls:
            break
        cls, n_cls = new, n_new
    # renumber classes in order of first appearance, keeping the initial state first
    order = np.full(n_cls, -1, dtype=np.int64)
    reps: list[int] = []
    for q in [dba.initial] + [q for q in range(n) if q != dba.initial]:
        c = cls[q]
        if order[c] < 0:
            order[c] = len(reps)
            reps.append(q)
    reps_arr = np.array(reps, dtype=np.int64)
    delta = order[cls[dba.delta[reps_arr]]].astype(np.int32)
    comps = dba.components[reps_arr] if dba.components is not None else None
    return DBA(
        delta,
        int(order[cls[dba.initial]]),
        dba.accepting[reps_arr],
        dba.letters,
        [dba.names[q] for q in reps],
        comps,
    )


def objective_automaton(objective: Objective, letters: Sequence[Label], max_states: int | None = None) -> DBA:
    """The reduced DBA of a conjunction of tasks."""
    parts = [task_automaton(t, letters) for t in objective.tasks]
    return minimize(product(parts, accept_all=True, max_states=max_states))


@dataclass
class SpecificationProduct:
    """B_pi = B_sys x B_test: its states are the *histories* of a test.

    ``dba.accepting[:, 0]`` is F_sys, ``dba.accepting[:, 1]`` is F_test;
    ``sys_state[h]``/``test_state[h]`` project a history onto each automaton.
    """

    dba: DBA
    sys: DBA
    test: DBA

    @property
    def components(self) -> np.ndarray:
        """``int32[n_hist, 2]``: the ``(q_sys, q_test)`` of each history (a product always has them)."""
        comps = self.dba.components
        if comps is None:
            raise ValueError("the specification product lost its components")
        return comps

    @property
    def sys_state(self) -> np.ndarray:
        return self.components[:, 0]

    @property
    def test_state(self) -> np.ndarray:
        return self.components[:, 1]

    @property
    def accepting_sys(self) -> np.ndarray:
        return self.dba.accepting[:, 0]

    @property
    def accepting_test(self) -> np.ndarray:
        return self.dba.accepting[:, 1]

    def history_name(self, h: int) -> str:
        """The opaque, stable name of history ``h`` used in outputs."""
        return f"q{h}"

    def describe(self, h: int) -> str:
        """What history ``h`` means, in words (the progress of both objectives)."""
        s, t = self.components[h]
        bits = [b for b in (self.sys.names[s], self.test.names[t]) if b]
        return "; ".join(bits) or "start"


def specification_product(sys_objective: Objective, test_objective: Objective, letters: Sequence[Label], max_states: int | None = None) -> SpecificationProduct:
    """Build B_sys, B_test and their reachable product B_pi (docs/method.md §3).

    ``max_states`` bounds every product explored (:class:`ProblemTooLarge` beyond it).
    """
    b_sys = objective_automaton(sys_objective, letters, max_states)
    b_test = objective_automaton(test_objective, letters, max_states)
    pi = product([b_sys, b_test], accept_all=False, max_states=max_states)
    # B_pi's components must stay those of B_sys/B_test (no further merging of
    # histories with different (q_sys, q_test)), so it is not minimised again.
    return SpecificationProduct(pi, b_sys, b_test)
