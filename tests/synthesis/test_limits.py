"""Resource limits with a clear word (issue 13, point 3)."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from experiments.cli.cli import main
from synthesis.model.errors import ProblemTooLarge
from synthesis.pipeline import SynthesisOptions, remaining_time, synthesize
from synthesis.problems.builtins import BUILTINS
from synthesis.problems.files import problem_from_dict
from synthesis.problems.limits import MAX_GRAPH_EDGES, check_size, estimate_size
from synthesis.problems.load import load_problem


def grid_problem(n: int, test: str = "F I1 & F I2") -> dict:
    rows = []
    for r in range(n):
        row = ["."] * n
        if r == 0:
            row[0], row[-1] = "I1", "T"
        if r == n - 1:
            row[0], row[-1] = "S", "I2"
        rows.append(" ".join(row))
    return {
        "name": f"empty-{n}",
        "system": {"grid": "\n".join(rows), "start": "S", "terminal": ["T"]},
        "labels": {"goal": ["T"], "I1": ["I1"], "I2": ["I2"]},
        "objectives": {"system": "F goal", "test": test},
        "environment": {"kind": "reactive"},
    }


def test_every_builtin_is_within_the_limit() -> None:
    for name, make in BUILTINS.items():
        est = check_size(make(), MAX_GRAPH_EDGES)
        assert est is not None and est.edges <= MAX_GRAPH_EDGES, name


def test_huge_grid_is_refused_fast_with_the_way_on(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = grid_problem(1000)
    text = (
        f'name = "big"\n[system]\ngrid = """\n{data["system"]["grid"]}\n"""\nstart = "S"\nterminal = ["T"]\n'
        '[labels]\ngoal = ["T"]\nI1 = ["I1"]\nI2 = ["I2"]\n[objectives]\nsystem = "F goal"\ntest = "F I1 & F I2"\n'
        '[environment]\nkind = "reactive"\n'
    )
    (tmp_path / "big.toml").write_text(text)
    t0 = time.perf_counter()
    assert main(["synthesize", str(tmp_path / "big.toml"), "-q"]) == 2
    assert time.perf_counter() - t0 < 30
    err = capsys.readouterr().err
    assert err.count("error: ") == 1 and "1000000 cells" in err and "--no-size-limit" in err


def test_large_product_is_refused_with_an_estimate() -> None:
    problem = problem_from_dict(grid_problem(300))  # 90 000 cells, about 360 000 moves
    with pytest.raises(ProblemTooLarge, match="product-graph edges.*GB.*--no-size-limit"):
        synthesize(problem)
    est = estimate_size(problem)
    assert est.moves > 300_000 and est.histories >= 2


def test_many_visits_are_counted_exactly_before_refusing() -> None:
    """The cheap bound is loose; the exact history count decides, and the exploration is capped."""
    props = [f"p{i}" for i in range(12)]
    data = grid_problem(8, " & ".join(f"F {p}" for p in props))
    for i, p in enumerate(props):
        data["labels"][p] = [[1 + i // 6, i % 6]]
    problem = problem_from_dict(data)
    assert estimate_size(problem).histories == 2 * 2**12
    with pytest.raises(ProblemTooLarge, match="histories"):
        check_size(problem, 20_000)


def test_the_limit_is_an_option() -> None:
    problem = load_problem("small-reactive")
    with pytest.raises(ProblemTooLarge):
        synthesize(problem, SynthesisOptions(max_graph_edges=10))
    synthesize(problem, SynthesisOptions(max_graph_edges=None))


def test_time_limit_counts_graph_building() -> None:
    problem = load_problem("small-reactive")
    with pytest.raises(TimeoutError, match="product graphs"):
        remaining_time(problem, SynthesisOptions(time_limit=1.0), spent=1.5)
    left = remaining_time(problem, SynthesisOptions(time_limit=10.0), spent=2.5)
    assert left.time_limit == pytest.approx(7.5)
    assert remaining_time(problem, SynthesisOptions(), spent=99.0).time_limit is None
