"""Objectives: the formula syntax of problem files and the sub-task patterns of docs/method.md §2.

A formula is parsed into a small syntax tree, split at its top-level conjunction and
each conjunct is classified as one of the patterns

=========================  ==============================  ==============
pattern                    formula                         allowed in
=========================  ==============================  ==============
``visit``                  ``F p``                         test, system
``sequenced``              ``F(p1 & F(p2 & ... F pm))``    test, system
``safety``                 ``G !p`` (any ``G p``)          system
``reaction``               ``G(p -> q)``                   system
``delayed``                ``G(p -> F q)``                 system
=========================  ==============================  ==============

where ``p``, ``q`` are Boolean combinations of propositions. Anything else is
rejected with a :class:`~synthesis.model.errors.ProblemError` that quotes the part.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass

from .errors import ProblemError

# ----------------------------------------------------------------------------- syntax


@dataclass(frozen=True)
class Prop:
    name: str


@dataclass(frozen=True)
class Const:
    value: bool


@dataclass(frozen=True)
class Not:
    arg: Formula


@dataclass(frozen=True)
class BinOp:
    op: str  # "&", "|", "->", "U"
    left: Formula
    right: Formula


@dataclass(frozen=True)
class Temporal:
    op: str  # "F", "G", "X"
    arg: Formula


Formula = Prop | Const | Not | BinOp | Temporal

_TOKEN = re.compile(r"\s*(->|[()!&|]|[A-Za-z_][A-Za-z0-9_]*|\S)")
_BINDING = {"->": 1, "|": 2, "&": 3, "U": 4}
_UNARY_TEMPORAL = {"F", "G", "X"}
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")

RESERVED = frozenset({"true", "false", "F", "G", "X", "U"})
"""Words of the formula syntax: never proposition names (``true`` as a label would
silently turn ``F true`` into a visit of that label's cells)."""

MAX_FORMULA_CHARS = 10_000
"""Longest formula accepted (far beyond any objective whose automaton can be built)."""

MAX_FORMULA_DEPTH = 200
"""Deepest syntax tree accepted: nesting of parentheses, ``!``, ``F``/``G``/``X`` and
chains of binary operators. Bounded so that every recursive walk of a formula stays far
below Python's recursion limit; a deeper formula is refused with a clear error."""


def is_proposition_name(name: object) -> bool:
    """Whether ``name`` can name a proposition: an identifier that is not a reserved word."""
    return isinstance(name, str) and _NAME.fullmatch(name) is not None and name not in RESERVED


def check_proposition_name(name: object, where: str) -> None:
    """Raise :class:`ProblemError` unless ``name`` can name a proposition."""
    if not isinstance(name, str) or _NAME.fullmatch(name) is None:
        raise ProblemError(f"{where}: {name!r} is not a proposition name (letters, digits and _, not starting with a digit)")
    if name in RESERVED:
        raise ProblemError(f"{where}: {name!r} is a reserved word of the formula syntax ({', '.join(sorted(RESERVED))}), not a proposition name")


def _tokenize(text: str) -> list[tuple[str, int]]:
    tokens: list[tuple[str, int]] = []
    pos = 0
    text = text.rstrip()
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None:  # only trailing whitespace left
            break
        tok = m.group(1)
        if not (re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", tok) or tok in {"->", "(", ")", "!", "&", "|"}):
            raise ProblemError(f"unexpected character {tok!r} at position {m.start(1)} of formula {text!r}")
        tokens.append((tok, m.start(1)))
        pos = m.end()
    return tokens


class _Parser:
    def __init__(self, text: str) -> None:
        self.text = text
        self.tokens = _tokenize(text)
        self.i = 0
        self.depth = 0  # nesting of the recursive descent, bounded by MAX_FORMULA_DEPTH

    def nest(self) -> None:
        self.depth += 1
        if self.depth > MAX_FORMULA_DEPTH:
            raise self.error(f"the formula nests deeper than {MAX_FORMULA_DEPTH} levels")

    def error(self, what: str) -> ProblemError:
        if self.i < len(self.tokens):
            tok, pos = self.tokens[self.i]
            where = f"at {tok!r} (position {pos})"
        else:
            where = "at the end"
        return ProblemError(f"{what} {where} in formula {_clip(self.text)!r}")

    def peek(self) -> str | None:
        return self.tokens[self.i][0] if self.i < len(self.tokens) else None

    def take(self) -> str:
        tok = self.tokens[self.i][0]
        self.i += 1
        return tok

    def parse(self) -> Formula:
        if not self.tokens:
            raise ProblemError("empty formula")
        f = self.binary(1)
        if self.i != len(self.tokens):
            raise self.error("unexpected token")
        return f

    def binary(self, min_binding: int) -> Formula:
        left = self.unary()
        while (tok := self.peek()) in _BINDING and _BINDING[tok] >= min_binding:
            self.take()
            # "->" is right associative, the others left associative
            self.nest()
            right = self.binary(_BINDING[tok] if tok == "->" else _BINDING[tok] + 1)
            self.depth -= 1
            left = BinOp(tok, left, right)
        return left

    def unary(self) -> Formula:
        tok = self.peek()
        if tok is None:
            raise self.error("an operand is missing")
        if tok == "!":
            self.take()
            self.nest()
            f: Formula = Not(self.unary())
            self.depth -= 1
            return f
        if tok in _UNARY_TEMPORAL:
            self.take()
            self.nest()
            f = Temporal(tok, self.unary())
            self.depth -= 1
            return f
        if tok == "(":
            self.take()
            self.nest()
            f = self.binary(1)
            if self.peek() != ")":
                raise self.error("missing ')'")
            self.take()
            self.depth -= 1
            return f
        if tok in ("true", "false"):
            self.take()
            return Const(tok == "true")
        if tok in (")", "&", "|", "->", "U"):
            raise self.error("expected a proposition, '!', 'F', 'G', 'X' or '('")
        self.take()
        return Prop(tok)


def parse_formula(text: str) -> Formula:
    """Parse a formula of the problem-file syntax into a syntax tree.

    Raises
    ------
    ProblemError
        On a syntax error; the message gives the position.
    """
    if len(text) > MAX_FORMULA_CHARS:
        raise ProblemError(f"formula of {len(text)} characters is longer than the {MAX_FORMULA_CHARS} accepted")
    tree = _Parser(text).parse()
    depth = formula_depth(tree)
    if depth > MAX_FORMULA_DEPTH:
        raise ProblemError(f"formula {_clip(text)!r} is {depth} levels deep (chains of operators count), more than the {MAX_FORMULA_DEPTH} accepted")
    return tree


def _clip(text: str, limit: int = 80) -> str:
    return text if len(text) <= limit else text[: limit - 3] + "..."


def formula_depth(f: Formula) -> int:
    """Height of the syntax tree, computed without recursion (any tree is safe)."""
    deepest = 0
    stack: list[tuple[Formula, int]] = [(f, 1)]
    while stack:
        node, d = stack.pop()
        deepest = max(deepest, d)
        if isinstance(node, (Not, Temporal)):
            stack.append((node.arg, d + 1))
        elif isinstance(node, BinOp):
            stack.append((node.left, d + 1))
            stack.append((node.right, d + 1))
    return deepest


def to_text(f: Formula) -> str:
    """Write a syntax tree back as formula text (fully parenthesised where needed)."""
    if isinstance(f, Prop):
        return f.name
    if isinstance(f, Const):
        return "true" if f.value else "false"
    if isinstance(f, Not):
        return f"!{to_text(f.arg)}"  # a binary operand is already parenthesised
    if isinstance(f, Temporal):
        inner = to_text(f.arg)
        if isinstance(f.arg, BinOp):
            return f"{f.op}{inner}"
        return f"{f.op} {inner}" if isinstance(f.arg, (Prop, Const)) else f"{f.op}({inner})"
    return f"({to_text(f.left)} {f.op} {to_text(f.right)})"


# ------------------------------------------------------------------- propositional


def is_propositional(f: Formula) -> bool:
    """Whether ``f`` is a Boolean combination of propositions (no temporal operator)."""
    if isinstance(f, (Prop, Const)):
        return True
    if isinstance(f, Not):
        return is_propositional(f.arg)
    if isinstance(f, BinOp):
        return f.op != "U" and is_propositional(f.left) and is_propositional(f.right)
    return False


def propositions(f: Formula) -> set[str]:
    """The proposition names that occur in ``f``."""
    if isinstance(f, Prop):
        return {f.name}
    if isinstance(f, Const):
        return set()
    if isinstance(f, (Not, Temporal)):
        return propositions(f.arg)
    return propositions(f.left) | propositions(f.right)


def holds(f: Formula, label: frozenset[str]) -> bool:
    """Evaluate a propositional formula on a label (the set of propositions true in a state)."""
    if isinstance(f, Prop):
        return f.name in label
    if isinstance(f, Const):
        return f.value
    if isinstance(f, Not):
        return not holds(f.arg, label)
    if isinstance(f, BinOp):
        if f.op == "&":
            return holds(f.left, label) and holds(f.right, label)
        if f.op == "|":
            return holds(f.left, label) or holds(f.right, label)
        if f.op == "->":
            return (not holds(f.left, label)) or holds(f.right, label)
    raise TypeError(f"not a propositional formula: {to_text(f)}")


# ------------------------------------------------------------------------ patterns


@dataclass(frozen=True)
class Task:
    """One sub-task of an objective.

    ``kind`` is one of ``visit``, ``sequenced``, ``safety``, ``reaction``, ``delayed``.
    ``props`` holds its propositional formulas: ``[p]`` for a visit, ``[p1..pm]`` for
    a sequenced visit, ``[q]`` for safety ``G q`` (``q`` must always hold),
    ``[p, q]`` for the two reactions.
    """

    kind: str
    props: tuple[Formula, ...]
    text: str

    @property
    def is_visit(self) -> bool:
        return self.kind in ("visit", "sequenced")


@dataclass(frozen=True)
class Objective:
    """A conjunction of sub-tasks, as written by the user."""

    text: str
    tasks: tuple[Task, ...]

    def propositions(self) -> set[str]:
        return set().union(*(propositions(p) for t in self.tasks for p in t.props))


def _conjuncts(f: Formula) -> list[Formula]:
    if isinstance(f, BinOp) and f.op == "&":
        return _conjuncts(f.left) + _conjuncts(f.right)
    return [f]


def _sequence(f: Formula) -> list[Formula] | None:
    """``F(p1 & F(p2 & ... F pm))`` -> ``[p1..pm]``; ``None`` if ``f`` is not of that shape."""
    if not (isinstance(f, Temporal) and f.op == "F"):
        return None
    body = f.arg
    if is_propositional(body):
        return [body]
    parts = _conjuncts(body)
    nested = [p for p in parts if not is_propositional(p)]
    if len(nested) != 1:
        return None
    rest = _sequence(nested[0])
    if rest is None:
        return None
    here = [p for p in parts if is_propositional(p)]
    if not here:  # F(F(...)) is F(...)
        return rest
    head: Formula = here[0]
    for p in here[1:]:
        head = BinOp("&", head, p)
    return [head] + rest


def _classify(f: Formula) -> Task | None:
    text = to_text(f)
    seq = _sequence(f)
    if seq is not None:
        return Task("visit" if len(seq) == 1 else "sequenced", tuple(seq), text)
    if isinstance(f, Temporal) and f.op == "G":
        body = f.arg
        if is_propositional(body):
            if isinstance(body, BinOp) and body.op == "->":
                return Task("reaction", (body.left, body.right), text)
            return Task("safety", (body,), text)
        if (
            isinstance(body, BinOp)
            and body.op == "->"
            and is_propositional(body.left)
            and isinstance(body.right, Temporal)
            and body.right.op == "F"
            and is_propositional(body.right.arg)
        ):
            return Task("delayed", (body.left, body.right.arg), text)
    return None


_FRAGMENT = "F p, F(p1 & F(p2 & ... F pm)), G !p, G(p -> q) or G(p -> F q), with p, q Boolean combinations of propositions"


def parse_objective(text: str, role: str) -> Objective:
    """Parse and classify an objective.

    Parameters
    ----------
    text
        The formula, e.g. ``"F goal & G !unsafe"``.
    role
        ``"system"`` or ``"test"``; the test objective may hold only visit and
        sequenced-visit tasks.

    Raises
    ------
    ProblemError
        On a syntax error, or a conjunct outside the fragment of docs/method.md §2 (the
        message names the conjunct).
    """
    if not isinstance(text, str):
        raise ProblemError(f"the {role} objective must be a string, got {type(text).__name__}")
    if not text.strip():
        raise ProblemError(f"the {role} objective is empty")
    try:
        tree = parse_formula(text)
    except ProblemError as exc:
        raise ProblemError(f"the {role} objective: {exc}") from None
    tasks: list[Task] = []
    for part in _conjuncts(tree):
        task = _classify(part)
        if task is None:
            raise ProblemError(f"the {role} objective part {to_text(part)!r} is outside the supported fragment ({_FRAGMENT})")
        if role == "test" and not task.is_visit:
            raise ProblemError(
                f"the test objective part {task.text!r} is a {task.kind} task; a test objective may hold only visits F p and sequenced visits F(p1 & F p2 ...)"
            )
        tasks.append(task)
    if not any(t.is_visit for t in tasks):
        raise ProblemError(f"the {role} objective {text!r} needs at least one visit task F p")
    return Objective(text=text, tasks=tuple(tasks))


def check_propositions(objective: Objective, known: Iterable[str], role: str) -> None:
    """Raise :class:`ProblemError` naming the first proposition that no state can carry."""
    known = set(known)
    for task in objective.tasks:
        for p in task.props:
            unknown = sorted(propositions(p) - known)
            if unknown:
                raise ProblemError(
                    f"unknown proposition {unknown[0]!r} in the {role} objective part {task.text!r} (known: {', '.join(sorted(known)) or 'none'})"
                )
