"""Bad problem files get one clear ProblemError that names what is wrong (issue 13, point 4).

Each case edits a valid problem; the loader must refuse it with a message holding the
given words, and never fail with anything but :class:`ProblemError`.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from synthesis.model.errors import ProblemError
from synthesis.model.specs import MAX_FORMULA_DEPTH, parse_objective
from synthesis.problems.files import MAX_FILE_BYTES, load_problem_file, problem_from_dict
from tests.testing_problems import SMALL_REACTIVE_TOML

GRID = SMALL_REACTIVE_TOML

GRAPH = """[system]
states = ["a", "b", "c"]
edges = [["a", "b"], ["b", "c"], ["a", "c"]]
start = "a"
terminal = ["c"]
[labels]
goal = ["c"]
mid = ["b"]
[objectives]
system = "F goal"
test = "F mid"
[environment]
kind = "reactive"
"""

ENV = 'kind = "reactive"'

CASES = [
    # reserved words and non-names as propositions
    (GRID, 'I1 = ["I1"]', 'I1 = ["I1"]\ntrue = ["S"]', "reserved word"),
    (GRID, 'I1 = ["I1"]', 'I1 = ["I1"]\nfalse = ["S"]', "reserved word"),
    (GRID, 'I1 = ["I1"]', 'I1 = ["I1"]\nF = ["S"]', "reserved word"),
    (GRID, 'I1 = ["I1"]', 'I1 = ["I1"]\nU = ["S"]', "reserved word"),
    (GRID, 'I1 = ["I1"]', 'I1 = ["I1"]\n"a b" = ["S"]', "not a proposition name"),
    (GRID, 'I1 = ["I1"]', 'I1 = ["I1"]\n"" = ["S"]', "not a proposition name"),
    (GRAPH, 'mid = ["b"]', 'mid = ["b"]\ntrue = ["a"]', "reserved word"),
    # grid tokens are names
    (GRID, "I1 .  T", "I1 !@ T", "token '!@'"),
    (GRID, "I1 .  T", "I1 12 T", "token '12'"),
    (GRID, "I1 .  T", "I1 #x T", "token '#x'"),
    # misspelled keys are named, not reported as the missing key
    (GRID, 'terminal = ["T"]', 'termnal = ["T"]', "unknown key 'termnal'"),
    (GRID, 'start = "S"', 'strat = "S"', "unknown key 'strat'"),
    (GRID, ENV, 'knd = "reactive"', "unknown key 'knd'"),
    (GRAPH, 'start = "a"', 'strat = "a"', "unknown key 'strat'"),
    # booleans are not numbers, NaN and infinities are not seconds
    (GRID, 'start = "S"', "start = [true, false]", "neither a token nor a [row, col] cell"),
    (GRID, ENV, ENV + "\ntime_limit = true", "time_limit"),
    (GRID, ENV, ENV + "\ntime_limit = nan", "time_limit"),
    (GRID, ENV, ENV + "\ntime_limit = inf", "time_limit"),
    (GRID, ENV, ENV + "\ntime_limit = -1", "time_limit"),
    (GRID, ENV, 'kind = "mixed"\nstatic = [[[true, 0], [0, 0]]]', "neither a token nor a [row, col] cell"),
    # empty objectives say which
    (GRID, 'system = "F goal"', 'system = ""', "the system objective is empty"),
    (GRID, 'test = "F I1 & F I2"', 'test = "  "', "the test objective is empty"),
    # options validated before synthesis
    (GRID, ENV, ENV + '\nsetting = "bogus"', "setting"),
    (GRID, ENV, ENV + "\nsetting = 3", "setting"),
    (GRID, ENV, ENV + '\nstatic = [["S", "I1"]]', "for mixed and agent problems"),
    (GRID, ENV, "kind = 1", "kind"),
    (GRID, ENV, 'kind = ["reactive"]', "kind"),
    # names and descriptions
    (GRID, 'name = "t"', "name = 5", "`name`"),
    (GRID, 'name = "t"', 'name = ""', "`name`"),
    (GRID, 'name = "t"', 'name = "a\\nb"', "`name`"),
    (GRID, 'name = "t"', 'name = "t"\ndescription = 5', "`description`"),
    # graph shapes
    (GRAPH, 'mid = ["b"]', 'mid = [["b"]]', "[labels] mid"),
    (GRAPH, 'terminal = ["c"]', 'terminal = [["c"]]', "[system] terminal"),
    (GRAPH, 'states = ["a", "b", "c"]', 'states = ["a", "b", "c", ""]', "[system] states"),
    (GRAPH, 'start = "a"', 'start = "a"\nrestrictable = [[1, 2]]', "restrictable"),
    (GRAPH, ENV, 'kind = "agent"\n[environment.agent]\ncells = 3\nstart = 1\nparks = 2', "cells"),
    (GRID, ENV, ENV + '\n[environment.agent]\ncells = [[0,1]]\nstart = [0,1]\nparks = [{name="p", from=[[0,1]]}]', 'kind = "agent"'),
]


@pytest.mark.parametrize("base,old,new,words", CASES, ids=[f"{i}-{c[3][:20]}" for i, c in enumerate(CASES)])
def test_bad_problem_is_named(tmp_path: Path, base: str, old: str, new: str, words: str) -> None:
    assert old in base
    path = tmp_path / "p.toml"
    path.write_text(base.replace(old, new, 1))
    with pytest.raises(ProblemError) as info:
        load_problem_file(path)
    assert words in str(info.value)


def test_the_bases_are_valid(tmp_path: Path) -> None:
    for i, text in enumerate((GRID, GRAPH)):
        (tmp_path / f"{i}.toml").write_text(text)
        load_problem_file(tmp_path / f"{i}.toml")


@pytest.mark.parametrize(
    "formula",
    [
        "F(" * 5000 + "a" + ")" * 5000,
        "F " + "!" * 9000 + "a",
        " & ".join(["F a"] * 2000),
        "F(" + " | ".join(["a"] * 4000) + ")",
        "G(" + " -> ".join(["a"] * 3000) + ")",
        "F a & " * 100_000 + "F a",
    ],
    ids=["nested", "negations", "conjunction", "disjunction", "implications", "huge"],
)
def test_formulas_of_any_size_get_an_answer(formula: str) -> None:
    """No RecursionError whatever the depth or length: a ProblemError that says why."""
    with pytest.raises(ProblemError, match="deep|longer than"):
        parse_objective(formula, "test")


def test_formulas_up_to_the_depth_limit_parse() -> None:
    depth = MAX_FORMULA_DEPTH // 2
    parse_objective(" & ".join(["F a"] * depth), "test")
    parse_objective("F(" * (depth - 1) + "a" + ")" * (depth - 1), "test")


def test_special_files_and_huge_files_are_refused(tmp_path: Path) -> None:
    with pytest.raises(ProblemError, match="directory|not a regular file"):
        load_problem_file(tmp_path)
    if os.path.exists("/dev/zero"):
        with pytest.raises(ProblemError, match="not a regular file"):
            load_problem_file("/dev/zero")
    big = tmp_path / "big.toml"
    with open(big, "wb") as fh:
        fh.truncate(MAX_FILE_BYTES + 1)
    with pytest.raises(ProblemError, match="larger than"):
        load_problem_file(big)
    if hasattr(os, "mkfifo"):
        fifo = tmp_path / "fifo.toml"
        os.mkfifo(fifo)
        with pytest.raises(ProblemError, match="not a regular file"):
            load_problem_file(fifo)  # must not block waiting for a writer


def test_problem_from_dict_rejects_reserved_names_from_python() -> None:
    import tomllib

    data = tomllib.loads(GRID.replace('I1 = ["I1"]', 'I1 = ["I1"]\nX = ["S"]'))
    with pytest.raises(ProblemError, match="reserved"):
        problem_from_dict(data)
