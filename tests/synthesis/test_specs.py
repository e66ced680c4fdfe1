"""Tests of :mod:`synthesis.model.specs`: the formula parser and the pattern classifier.

The parser is checked against an independent printer that writes a syntax tree with
the *fewest* parentheses the documented precedence allows
(``!``/``F``/``G``/``X`` > ``&`` > ``|`` > ``->``, ``->`` right associative,
``&`` and ``|`` left associative): if the parser got a precedence or an
associativity wrong, the minimal text would parse into a different tree.
Classification is checked on every pattern of method.md §2, including Boolean
combinations, and rejections must name the offending conjunct.
"""

from __future__ import annotations

import random
import re

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from synthesis.model.errors import ProblemError
from synthesis.model.specs import (
    BinOp,
    Const,
    Formula,
    Not,
    Prop,
    Temporal,
    check_propositions,
    holds,
    is_propositional,
    parse_formula,
    parse_objective,
    propositions,
    to_text,
)

# ----------------------------------------------------------------- reference printer

#: Binding strength of each operator in the problem-file syntax (higher binds tighter).
PREC: dict[str, int] = {"->": 1, "|": 2, "&": 3}
UNARY_PREC = 5
ATOM_PREC = 6


def prec(f: Formula) -> int:
    """Binding strength of the top operator of ``f``."""
    if isinstance(f, (Prop, Const)):
        return ATOM_PREC
    if isinstance(f, (Not, Temporal)):
        return UNARY_PREC
    assert isinstance(f, BinOp)
    return PREC[f.op]


def minimal_text(f: Formula, compact: bool = False) -> str:
    """Write ``f`` with the fewest parentheses the documented precedence needs.

    With ``compact`` no blanks are written where the tokenizer does not need them.
    """
    if isinstance(f, Prop):
        return f.name
    if isinstance(f, Const):
        return "true" if f.value else "false"
    if isinstance(f, (Not, Temporal)):
        op = "!" if isinstance(f, Not) else f.op
        inner = minimal_text(f.arg, compact)
        if prec(f.arg) < UNARY_PREC:
            inner = f"({inner})"
        # "F" followed by a name needs a blank; "!" never does
        needs_blank = op != "!" and not (compact and inner[0] in "(!")
        sep = " " if needs_blank else ""
        return f"{op}{sep}{inner}"
    assert isinstance(f, BinOp)
    p = PREC[f.op]
    left = minimal_text(f.left, compact)
    right = minimal_text(f.right, compact)
    right_assoc = f.op == "->"
    if prec(f.left) < p or (right_assoc and prec(f.left) == p):
        left = f"({left})"
    if prec(f.right) < p or (not right_assoc and prec(f.right) == p):
        right = f"({right})"
    sep = "" if compact else " "
    return f"{left}{sep}{f.op}{sep}{right}"


def random_formula(rng: random.Random, depth: int, names: list[str], temporal: bool = True) -> Formula:
    """A random syntax tree over ``names`` (with F/G/X only when ``temporal``)."""
    if depth == 0 or rng.random() < 0.25:
        if rng.random() < 0.1:
            return Const(rng.random() < 0.5)
        return Prop(rng.choice(names))
    r = rng.random()
    if r < 0.2:
        return Not(random_formula(rng, depth - 1, names, temporal))
    if temporal and r < 0.35:
        return Temporal(rng.choice("FGX"), random_formula(rng, depth - 1, names, temporal))
    op = rng.choice(["&", "|", "->"])
    return BinOp(op, random_formula(rng, depth - 1, names, temporal), random_formula(rng, depth - 1, names, temporal))


# ------------------------------------------------------------------ reference evaluator


def evaluate(f: Formula, label: frozenset[str]) -> bool:
    """Truth of a propositional tree on a label, written independently of :func:`holds`."""
    match f:
        case Prop(name=n):
            return n in label
        case Const(value=v):
            return v
        case Not(arg=a):
            return not evaluate(a, label)
        case BinOp(op="&", left=a, right=b):
            return evaluate(a, label) and evaluate(b, label)
        case BinOp(op="|", left=a, right=b):
            return evaluate(a, label) or evaluate(b, label)
        case BinOp(op="->", left=a, right=b):
            return (not evaluate(a, label)) or evaluate(b, label)
    raise AssertionError(f"not propositional: {f!r}")


# ------------------------------------------------------------------------- parser

P, Q, R, S = Prop("p"), Prop("q"), Prop("r"), Prop("s")


@pytest.mark.parametrize(
    "text, tree",
    [
        ("p", P),
        ("!p & q", BinOp("&", Not(P), Q)),
        ("!(p & q)", Not(BinOp("&", P, Q))),
        ("p | q & r", BinOp("|", P, BinOp("&", Q, R))),
        ("p & q | r", BinOp("|", BinOp("&", P, Q), R)),
        ("p -> q | r", BinOp("->", P, BinOp("|", Q, R))),
        ("p | q -> r", BinOp("->", BinOp("|", P, Q), R)),
        ("p -> q -> r", BinOp("->", P, BinOp("->", Q, R))),
        ("(p -> q) -> r", BinOp("->", BinOp("->", P, Q), R)),
        ("p & q & r", BinOp("&", BinOp("&", P, Q), R)),
        ("p | q | r", BinOp("|", BinOp("|", P, Q), R)),
        ("p & q | r & s -> p", BinOp("->", BinOp("|", BinOp("&", P, Q), BinOp("&", R, S)), P)),
        ("F p & q", BinOp("&", Temporal("F", P), Q)),
        ("F (p & q)", Temporal("F", BinOp("&", P, Q))),
        ("G !p", Temporal("G", Not(P))),
        ("!F p", Not(Temporal("F", P))),
        ("F G p", Temporal("F", Temporal("G", P))),
        ("X p | q", BinOp("|", Temporal("X", P), Q)),
        ("G(p -> F q)", Temporal("G", BinOp("->", P, Temporal("F", Q)))),
        ("G p -> F q", BinOp("->", Temporal("G", P), Temporal("F", Q))),
        ("!p&q|r->s", BinOp("->", BinOp("|", BinOp("&", Not(P), Q), R), S)),
        ("true & !false", BinOp("&", Const(True), Not(Const(False)))),
        ("  F   p  ", Temporal("F", P)),
        ("Fp", Prop("Fp")),  # a name, not F applied to p
        ("F_1 & G2", BinOp("&", Prop("F_1"), Prop("G2"))),
    ],
)
def test_parse_precedence_table(text: str, tree: Formula) -> None:
    """Hand-written cases of precedence, associativity and unary operators."""
    assert parse_formula(text) == tree


def test_parse_minimal_text_recovers_random_trees() -> None:
    """300 random trees, written with minimal parentheses (spaced and compact), parse back exactly."""
    rng = random.Random(20240501)
    for _ in range(300):
        f = random_formula(rng, 4, ["p", "q", "r", "s"])
        for compact in (False, True):
            text = minimal_text(f, compact)
            assert parse_formula(text) == f, (text, f)


@settings(max_examples=200, deadline=None, derandomize=True)
@given(st.integers(min_value=0, max_value=2**32 - 1))
def test_to_text_round_trip(seed: int) -> None:
    """``to_text`` writes a tree that parses back to the same tree."""
    f = random_formula(random.Random(seed), 5, ["a", "b", "goal", "I1"])
    assert parse_formula(to_text(f)) == f


def test_holds_matches_reference_evaluator() -> None:
    """``holds`` agrees with an independent evaluator on random propositional formulas and labels."""
    rng = random.Random(7)
    names = ["a", "b", "c"]
    labels = [frozenset(n for i, n in enumerate(names) if m >> i & 1) for m in range(8)]
    for _ in range(300):
        f = random_formula(rng, 4, names, temporal=False)
        assert is_propositional(f)
        for lab in labels:
            assert holds(f, lab) == evaluate(f, lab), (to_text(f), lab)
        assert propositions(f) <= set(names)


@pytest.mark.parametrize(
    "text, position",
    [
        ("F (a & )", 7),
        ("F a)", 3),
        ("a $ b", 2),
        ("a b", 2),
        ("&a", 0),
        ("  F a)", 5),
        ("G(a -> -> b)", 7),
        ("F(a | ) & F b", 6),
        ("a # b", 2),
    ],
)
def test_syntax_errors_give_positions(text: str, position: int) -> None:
    """A syntax error names the position of the offending token in the original text."""
    with pytest.raises(ProblemError) as err:
        parse_formula(text)
    msg = str(err.value)
    assert re.search(rf"\bposition {position}\b", msg), msg


@pytest.mark.parametrize("text", ["(a", "F(a & b", "a ->", "F", "!"])
def test_syntax_errors_at_the_end(text: str) -> None:
    """A formula that stops too early says so, and what is missing (not "ends too early at
    the end")."""
    with pytest.raises(ProblemError, match="at the end") as err:
        parse_formula(text)
    assert re.match(r"(an operand is missing|missing '\)') at the end in formula ", str(err.value)), str(err.value)


@pytest.mark.parametrize("text", ["", "   "])
def test_empty_formula(text: str) -> None:
    with pytest.raises(ProblemError, match="empty"):
        parse_formula(text)


def test_objective_must_be_a_string() -> None:
    with pytest.raises(ProblemError, match="must be a string"):
        parse_objective(["F a"], "system")  # type: ignore[arg-type]


# ------------------------------------------------------------------- classification


def _kinds(text: str, role: str = "system") -> list[tuple[str, list[Formula]]]:
    return [(t.kind, list(t.props)) for t in parse_objective(text, role).tasks]


A, B, C = Prop("a"), Prop("b"), Prop("c")


@pytest.mark.parametrize(
    "text, expected",
    [
        ("F a", [("visit", [A])]),
        ("F(a & !b)", [("visit", [BinOp("&", A, Not(B))])]),
        ("F (a | b) & F c", [("visit", [BinOp("|", A, B)]), ("visit", [C])]),
        ("F true", [("visit", [Const(True)])]),
        ("F(a & F b)", [("sequenced", [A, B])]),
        ("F(a & F(b & F c))", [("sequenced", [A, B, C])]),
        ("F(F b & a)", [("sequenced", [A, B])]),
        ("F((a | b) & F(!c))", [("sequenced", [BinOp("|", A, B), Not(C)])]),
        ("F(a & c & F b)", [("sequenced", [BinOp("&", A, C), B])]),
        ("F(a & F b) & F c", [("sequenced", [A, B]), ("visit", [C])]),
        ("F a & G !b", [("visit", [A]), ("safety", [Not(B)])]),
        ("F a & G(b & !c)", [("visit", [A]), ("safety", [BinOp("&", B, Not(C))])]),
        ("F a & G(b -> c)", [("visit", [A]), ("reaction", [B, C])]),
        ("F a & G(b -> c -> a)", [("visit", [A]), ("reaction", [B, BinOp("->", C, A)])]),
        ("F a & G((b -> c) -> a)", [("visit", [A]), ("reaction", [BinOp("->", B, C), A])]),
        ("F a & G(b -> F (c | a))", [("visit", [A]), ("delayed", [B, BinOp("|", C, A)])]),
        ("F a & G((b | c) -> F !a)", [("visit", [A]), ("delayed", [BinOp("|", B, C), Not(A)])]),
        (
            "F goal & G !unsafe & G((ice | rock) -> F dropoff)",
            [
                ("visit", [Prop("goal")]),
                ("safety", [Not(Prop("unsafe"))]),
                ("delayed", [BinOp("|", Prop("ice"), Prop("rock")), Prop("dropoff")]),
            ],
        ),
        ("F(beaver & F goal)", [("sequenced", [Prop("beaver"), Prop("goal")])]),
    ],
)
def test_classification(text: str, expected: list[tuple[str, list[Formula]]]) -> None:
    """Each conjunct is classified as its pattern, with its propositional parts in order."""
    assert _kinds(text) == expected


def test_test_objective_accepts_visits_and_sequences() -> None:
    assert _kinds("F I1 & F(I2 & F I3)", "test") == [
        ("visit", [Prop("I1")]),
        ("sequenced", [Prop("I2"), Prop("I3")]),
    ]


def test_objective_text_and_propositions() -> None:
    obj = parse_objective("F goal & G(p -> F (q | r))", "system")
    assert obj.text == "F goal & G(p -> F (q | r))"
    assert obj.propositions() == {"goal", "p", "q", "r"}
    assert [t.is_visit for t in obj.tasks] == [True, False]


def _rejected(text: str, role: str) -> str:
    with pytest.raises(ProblemError) as err:
        parse_objective(text, role)
    return str(err.value)


@pytest.mark.parametrize(
    "text, bad_part",
    [
        ("G F goal", "G F goal"),
        ("F goal & G F a", "G F a"),
        ("F a U b", "F a U b"),
        ("F goal & X a", "X a"),
        ("X a", "X a"),
        ("F G a", "F G a"),
        ("F goal & b", "b"),
        ("F(a & F b & F c)", "F(a & F b & F c)"),
        ("F(a | F b)", "F(a | F b)"),
        ("F goal & G(F a -> b)", "G(F a -> b)"),
        ("F goal & !F a", "!F a"),
        ("F goal & G(a -> X b)", "G(a -> X b)"),
        ("F goal & G(a -> F G b)", "G(a -> F G b)"),
        ("F goal | F a", "F goal | F a"),
    ],
)
def test_rejection_names_the_part(text: str, bad_part: str) -> None:
    """A conjunct outside the fragment is rejected, and the message quotes that conjunct only."""
    msg = _rejected(text, "system")
    quoted = to_text(parse_formula(bad_part))
    assert f"'{quoted}'" in msg, msg
    assert "outside the supported fragment" in msg
    assert "system objective" in msg
    if "&" in text and bad_part != text and "goal" in text and "goal" not in bad_part:
        assert "'F goal'" not in msg  # the valid conjunct is not blamed


@pytest.mark.parametrize(
    "text, bad_part, kind",
    [
        ("F a & G !b", "G !b", "safety"),
        ("G(a -> b) & F c", "G(a -> b)", "reaction"),
        ("F c & G(a -> F b)", "G(a -> F b)", "delayed"),
        ("G !b", "G !b", "safety"),
    ],
)
def test_test_objective_rejects_non_visits(text: str, bad_part: str, kind: str) -> None:
    """A test objective may hold visits only; the message names the task and its kind."""
    msg = _rejected(text, "test")
    assert f"'{to_text(parse_formula(bad_part))}'" in msg, msg
    assert f"is a {kind} task" in msg
    assert "test objective" in msg


@pytest.mark.parametrize("text", ["G !a", "G(a -> b) & G !c", "G(a -> F b)"])
def test_system_objective_needs_a_visit(text: str) -> None:
    msg = _rejected(text, "system")
    assert "needs at least one visit" in msg
    assert text in msg


def test_syntax_error_inside_objective_has_position() -> None:
    msg = _rejected("F goal & G(a ->)", "system")
    assert "position 15" in msg


def test_check_propositions_names_unknown() -> None:
    obj = parse_objective("F goal & G(p -> F zz)", "system")
    check_propositions(obj, {"goal", "p", "zz"}, "system")
    with pytest.raises(ProblemError) as err:
        check_propositions(obj, {"goal", "p"}, "system")
    msg = str(err.value)
    assert "'zz'" in msg and to_text(parse_formula("G(p -> F zz)")) in msg


@pytest.mark.parametrize("text", ["G(p -> F q)", "F(a & F b)", "G !(a & b)"])
def test_to_text_has_no_doubled_parentheses(text: str) -> None:
    """Quoted parts in messages should read as the user wrote them (no '((')."""
    assert "((" not in to_text(parse_formula(text))
