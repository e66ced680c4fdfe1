"""Tests of :mod:`synthesis.graphs.automata` against an independent semantics of the fragment.

A finite execution ``w = l_0 ... l_n`` is read as the infinite word
``l_0 ... l_n l_n l_n ...`` (method.md §2). :func:`holds_on` evaluates every pattern
of the fragment on such a stutter-extended word directly from its LTL meaning, without
automata. The DBA of a task or an objective must then

* accept in the state reached after reading ``w`` exactly when the formula holds, and
* accept the lasso ``w l_n^omega`` in the Büchi sense (some state of the cycle that
  ``l_n`` closes is accepting) exactly when the formula holds.

Minimisation must not change the language (compared with the unminimised product) and
must leave no two states that are equivalent (every pair is separated by some word).
"""

from __future__ import annotations

import itertools
import random
from collections import deque
from dataclasses import dataclass

import numpy as np
import pytest

from synthesis.graphs.automata import DBA, minimize, objective_automaton, product, specification_product, task_automaton
from synthesis.model.specs import BinOp, Const, Formula, Not, Prop, parse_formula, parse_objective

Label = frozenset[str]
NAMES = ["a", "b", "c", "d"]

# ------------------------------------------------------------- reference semantics


def prop_holds(f: Formula, label: Label) -> bool:
    """Truth of a propositional formula on one label (independent of ``specs.holds``)."""
    if isinstance(f, Prop):
        return f.name in label
    if isinstance(f, Const):
        return f.value
    if isinstance(f, Not):
        return not prop_holds(f.arg, label)
    assert isinstance(f, BinOp)
    x, y = prop_holds(f.left, label), prop_holds(f.right, label)
    return {"&": x and y, "|": x or y, "->": (not x) or y}[f.op]


@dataclass(frozen=True)
class RefTask:
    """A task in the reference's own representation: its kind and propositional parts."""

    kind: str
    props: tuple[Formula, ...]

    def text(self) -> str:
        """The task as formula text of the problem-file syntax."""
        p = [_text(x) for x in self.props]
        if self.kind == "visit":
            return f"F({p[0]})"
        if self.kind == "sequenced":
            out = f"F({p[-1]})"
            for x in reversed(p[:-1]):
                out = f"F(({x}) & {out})"
            return out
        if self.kind == "safety":
            return f"G({p[0]})"
        if self.kind == "reaction":
            return f"G(({p[0]}) -> ({p[1]}))"
        if self.kind == "delayed":
            return f"G(({p[0]}) -> F({p[1]}))"
        raise AssertionError(self.kind)


def _text(f: Formula) -> str:
    if isinstance(f, Prop):
        return f.name
    if isinstance(f, Const):
        return "true" if f.value else "false"
    if isinstance(f, Not):
        return f"!({_text(f.arg)})"
    assert isinstance(f, BinOp)
    return f"({_text(f.left)}) {f.op} ({_text(f.right)})"


def holds_on(task: RefTask, word: list[Label]) -> bool:
    """Does ``task`` hold on ``word`` followed by its last letter forever?"""
    n = len(word)
    t = [[prop_holds(p, a) for a in word] for p in task.props]
    if task.kind in ("visit", "sequenced"):
        # F(p1 & F(p2 & ...)): positions i1 <= i2 <= ... <= im (F includes the present);
        # beyond the end the word repeats its last letter, which adds no new position
        i = 0
        for tp in t:
            while i < n and not tp[i]:
                i += 1
            if i == n:
                return False
        return True
    if task.kind == "safety":
        return all(t[0])
    if task.kind == "reaction":
        return all((not x) or y for x, y in zip(t[0], t[1], strict=True))
    if task.kind == "delayed":
        # for every i with p: some j >= i with q; positions after n repeat position n-1
        return all(not t[0][i] or any(t[1][i:]) for i in range(n))
    raise AssertionError(task.kind)


def random_prop(rng: random.Random, depth: int, names: list[str]) -> Formula:
    """A random propositional formula."""
    if depth == 0 or rng.random() < 0.45:
        if rng.random() < 0.05:
            return Const(rng.random() < 0.5)
        return Prop(rng.choice(names))
    r = rng.random()
    if r < 0.25:
        return Not(random_prop(rng, depth - 1, names))
    return BinOp(rng.choice(["&", "|", "->"]), random_prop(rng, depth - 1, names), random_prop(rng, depth - 1, names))


def random_task(rng: random.Random, names: list[str], kind: str | None = None) -> RefTask:
    """A random task of ``kind`` (or of a random kind)."""
    kind = kind or rng.choice(["visit", "sequenced", "safety", "reaction", "delayed"])
    k = {"visit": 1, "sequenced": rng.randint(2, 4), "safety": 1, "reaction": 2, "delayed": 2}[kind]
    return RefTask(kind, tuple(random_prop(rng, 2, names) for _ in range(k)))


def random_letters(rng: random.Random, names: list[str]) -> tuple[Label, ...]:
    """2..6 distinct random labels (the alphabet a transition system would give)."""
    all_labels = [frozenset(n for i, n in enumerate(names) if m >> i & 1) for m in range(2 ** len(names))]
    return tuple(rng.sample(all_labels, rng.randint(2, min(6, len(all_labels)))))


# ----------------------------------------------------------------- automaton helpers


def run(dba: DBA, word: list[Label]) -> int:
    """The state after reading ``word`` from the initial state."""
    q = dba.initial
    for a in word:
        q = int(dba.delta[q, dba.letters.index(a)])
    return q


def lasso_accepts(dba: DBA, word: list[Label], col: int = 0) -> bool:
    """Büchi acceptance of ``word`` followed by its last letter forever."""
    q = run(dba, word)
    a = dba.letters.index(word[-1])
    seen: list[int] = []
    while q not in seen:
        seen.append(q)
        q = int(dba.delta[q, a])
    cycle = seen[seen.index(q) :]
    return bool(any(dba.accepting[s, col] for s in cycle))


def all_words(letters: tuple[Label, ...], max_len: int) -> list[list[Label]]:
    """Every non-empty word of length at most ``max_len``."""
    return [list(w) for n in range(1, max_len + 1) for w in itertools.product(letters, repeat=n)]


def random_words(rng: random.Random, letters: tuple[Label, ...], count: int, max_len: int) -> list[list[Label]]:
    return [[rng.choice(letters) for _ in range(rng.randint(1, max_len))] for _ in range(count)]


def task_via_parser(task: RefTask):
    """The library's Task for ``task``, going through the parser and classifier."""
    obj = parse_objective(f"F true & {task.text()}", "system")
    parsed = obj.tasks[1]
    expected = {task.kind}
    if task.kind == "safety" and isinstance(task.props[0], BinOp) and task.props[0].op == "->":
        expected.add("reaction")  # G(p -> q) is both; the library calls it a reaction
    assert parsed.kind in expected, (task.text(), parsed.kind)
    return parsed


def distinguishable_pairs(dba: DBA) -> set[tuple[int, int]]:
    """Pairs of states separated by some word (acceptance differs after it), by backward fixpoint."""
    n = dba.n_states
    acc = [tuple(bool(x) for x in dba.accepting[q]) for q in range(n)]
    dist = {(p, q) for p in range(n) for q in range(n) if acc[p] != acc[q]}
    changed = True
    while changed:
        changed = False
        for p in range(n):
            for q in range(n):
                if (p, q) in dist:
                    continue
                if any((int(dba.delta[p, a]), int(dba.delta[q, a])) in dist for a in range(dba.delta.shape[1])):
                    dist.add((p, q))
                    changed = True
    return dist


def reachable_states(dba: DBA) -> set[int]:
    seen = {dba.initial}
    todo = deque([dba.initial])
    while todo:
        q = todo.popleft()
        for r in dba.delta[q]:
            if int(r) not in seen:
                seen.add(int(r))
                todo.append(int(r))
    return seen


# ---------------------------------------------------------------------- tests

KINDS = ["visit", "sequenced", "safety", "reaction", "delayed"]


@pytest.mark.parametrize("kind", KINDS)
def test_pattern_automaton_matches_semantics(kind: str) -> None:
    """Each pattern's DBA agrees with the reference on all short words and on random long ones."""
    rng = random.Random(KINDS.index(kind) + 11)
    for _ in range(40):
        letters = random_letters(rng, NAMES[:3])
        task = random_task(rng, NAMES[:3], kind)
        dba = task_automaton(task_via_parser(task), letters)
        words = all_words(letters, 3) + random_words(rng, letters, 150, 10)
        for w in words:
            want = holds_on(task, w)
            q = run(dba, w)
            assert bool(dba.accepting[q, 0]) == want, (task.text(), [sorted(a) for a in w])
            assert lasso_accepts(dba, w) == want, (task.text(), [sorted(a) for a in w])


@pytest.mark.parametrize("kind", KINDS)
def test_pattern_automaton_is_stutter_idempotent(kind: str) -> None:
    """Reading a letter twice leads where reading it once does (the finite-word reading relies on it)."""
    rng = random.Random(KINDS.index(kind) + 50)
    for _ in range(30):
        letters = random_letters(rng, NAMES)
        dba = task_automaton(task_via_parser(random_task(rng, NAMES, kind)), letters)
        d = dba.delta
        for a in range(len(letters)):
            assert np.array_equal(d[d[:, a], a], d[:, a])


def test_pattern_automaton_sizes() -> None:
    """The documented shapes: m+1 stages for a (sequenced) visit, a sink for safety/reaction, one pending state."""
    letters = tuple(frozenset(s) for s in [(), ("a",), ("b",), ("c",), ("a", "b")])
    cases = {
        "F a": 2,
        "F(a & F(b & F c))": 4,
        "G !a": 2,
        "G(a -> b)": 2,
        "G(a -> F b)": 2,
    }
    for text, n in cases.items():
        task = parse_objective(f"F true & {text}", "system").tasks[1]
        assert task_automaton(task, letters).n_states == n, text


@pytest.mark.parametrize("seed", range(12))
def test_objective_automaton_matches_semantics(seed: int) -> None:
    """Conjunctions (product + minimisation) agree with the conjunction of the reference semantics."""
    rng = random.Random(1000 + seed)
    for _ in range(6):
        letters = random_letters(rng, NAMES)
        tasks = [random_task(rng, NAMES) for _ in range(rng.randint(1, 4))]
        text = " & ".join(["F true"] + [t.text() for t in tasks])
        obj = parse_objective(text, "system")
        dba = objective_automaton(obj, letters)
        for w in all_words(letters, 3) + random_words(rng, letters, 200, 12):
            want = all(holds_on(t, w) for t in tasks)
            assert bool(dba.accepting[run(dba, w), 0]) == want, (text, [sorted(a) for a in w])
            assert lasso_accepts(dba, w) == want, (text, [sorted(a) for a in w])


@pytest.mark.parametrize("seed", range(12))
def test_minimisation_preserves_language_and_is_minimal(seed: int) -> None:
    """Minimised vs unminimised product: same acceptance on every word; no two equivalent states."""
    rng = random.Random(2000 + seed)
    for _ in range(6):
        letters = random_letters(rng, NAMES)
        tasks = [random_task(rng, NAMES) for _ in range(rng.randint(2, 4))]
        parsed = parse_objective(" & ".join(t.text() for t in tasks) + " & F true", "system").tasks
        parts = [task_automaton(t, letters) for t in parsed]
        raw = product(parts, accept_all=True)
        small = minimize(raw)
        assert small.n_states <= raw.n_states
        for w in all_words(letters, 3) + random_words(rng, letters, 200, 12):
            assert raw.accepting[run(raw, w), 0] == small.accepting[run(small, w), 0]
        # every state reachable, every pair of distinct states separated by a word
        assert reachable_states(small) == set(range(small.n_states))
        dist = distinguishable_pairs(small)
        for p in range(small.n_states):
            for q in range(p + 1, small.n_states):
                assert (p, q) in dist, f"states {p} and {q} of the minimised automaton are equivalent"
        # the minimal automaton has exactly as many states as the product has Moore classes
        raw_dist = distinguishable_pairs(raw)
        reach = sorted(reachable_states(raw))
        classes: list[int] = []
        for q in reach:
            if all((q, r) in raw_dist for r in classes):
                classes.append(q)
        assert small.n_states == len(classes)
        # the product's components really are the parts' states
        for q in range(raw.n_states):
            for a in range(len(letters)):
                nxt = raw.components[int(raw.delta[q, a])]
                assert [int(p.delta[c, a]) for p, c in zip(parts, raw.components[q], strict=True)] == list(nxt)
        # idempotence survives product and minimisation
        for a in range(len(letters)):
            assert np.array_equal(small.delta[small.delta[:, a], a], small.delta[:, a])


def test_minimize_merges_a_known_redundancy() -> None:
    """``F a & F a`` has the same minimal DBA as ``F a`` (2 states), not 2 x 2."""
    letters = (frozenset(), frozenset({"a"}))
    obj = parse_objective("F a & F a", "system")
    raw = product([task_automaton(t, letters) for t in obj.tasks])
    assert raw.n_states == 2  # reachable part only: both parts move together
    obj2 = parse_objective("F a & G(b -> F a) & F true", "system")
    letters2 = (frozenset(), frozenset({"a"}), frozenset({"b"}))
    dba = objective_automaton(obj2, letters2)
    # a pending "b" needs an "a" later, exactly like an unseen "F a": both non-accepting
    # states behave alike, so only 2 classes remain (accepting / not accepting)
    assert dba.n_states == 2


@pytest.mark.parametrize("seed", range(8))
def test_specification_product_is_the_product_of_sys_and_test(seed: int) -> None:
    """B_pi's components step as B_sys and B_test do, and its two acceptance columns are theirs."""
    rng = random.Random(3000 + seed)
    letters = random_letters(rng, NAMES)
    sys_tasks = [random_task(rng, NAMES, "visit")] + [random_task(rng, NAMES) for _ in range(rng.randint(0, 2))]
    test_tasks = [random_task(rng, NAMES, rng.choice(["visit", "sequenced"])) for _ in range(rng.randint(1, 3))]
    sys_obj = parse_objective(" & ".join(t.text() for t in sys_tasks), "system")
    test_obj = parse_objective(" & ".join(t.text() for t in test_tasks), "test")
    spec = specification_product(sys_obj, test_obj, letters)
    pi, bs, bt = spec.dba, spec.sys, spec.test
    assert tuple(pi.components[pi.initial]) == (bs.initial, bt.initial)
    for h in range(pi.n_states):
        cs, ct = (int(x) for x in pi.components[h])
        assert spec.accepting_sys[h] == bs.accepting[cs, 0]
        assert spec.accepting_test[h] == bt.accepting[ct, 0]
        for a in range(len(letters)):
            nxt = pi.components[int(pi.delta[h, a])]
            assert (int(nxt[0]), int(nxt[1])) == (int(bs.delta[cs, a]), int(bt.delta[ct, a]))
    # distinct histories are distinct component pairs (B_pi is not merged further)
    pairs = {tuple(int(x) for x in c) for c in pi.components}
    assert len(pairs) == pi.n_states
    assert reachable_states(pi) == set(range(pi.n_states))
    # and the two columns mean what the two objectives mean, on random words
    for w in random_words(rng, letters, 200, 10):
        h = run(pi, w)
        assert bool(spec.accepting_sys[h]) == all(holds_on(t, w) for t in sys_tasks)
        assert bool(spec.accepting_test[h]) == all(holds_on(t, w) for t in test_tasks)


def test_reference_semantics_sanity() -> None:
    """The reference evaluator itself, on hand-made words (guards the guard)."""
    A, B = Prop("a"), Prop("b")
    e, a, b, ab = frozenset(), frozenset("a"), frozenset("b"), frozenset("ab")
    seq = RefTask("sequenced", (A, B))
    assert holds_on(seq, [e, a, e, b]) and holds_on(seq, [ab]) and not holds_on(seq, [b, a])
    delayed = RefTask("delayed", (A, B))
    assert holds_on(delayed, [a, e, b]) and not holds_on(delayed, [b, a]) and holds_on(delayed, [ab])
    assert not holds_on(delayed, [a])  # a forever, b never
    assert holds_on(RefTask("reaction", (A, B)), [e, ab, b]) and not holds_on(RefTask("reaction", (A, B)), [a, b])
    assert holds_on(RefTask("safety", (Not(A),)), [e, b]) and not holds_on(RefTask("safety", (Not(A),)), [b, a])
    assert parse_formula(RefTask("sequenced", (A, B, A)).text()) is not None
