"""docs/problem-format.md is held to the loader: every key a section accepts is documented
in that section's table and every documented key is accepted; every complete TOML example
loads; the Python fuel example builds a problem; and a mixed problem's static area is what
the page says (it allows walls, it does not force them)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from synthesis.model.errors import ProblemError
from synthesis.problems import agent_section as agent_mod
from synthesis.problems import files as problems
from synthesis.problems.files import load_problem_file

DOC = Path(__file__).resolve().parents[2] / "docs" / "problem-format.md"
TEXT = DOC.read_text()


def documented_keys(heading: str) -> set[str]:
    """The first-column keys of the table under ``### heading`` (up to the next heading)."""
    start = TEXT.index(f"### {heading}\n")
    end = TEXT.find("\n#", start + 4)
    block = TEXT[start : end if end > 0 else None]
    return set(re.findall(r"^\| `([a-z_]+)` \|", block, flags=re.M))


SECTIONS = {
    "Top level": problems._TOP_KEYS,
    "`[system]`, a grid": problems._GRID_KEYS,
    "`[system]`, a graph": problems._GRAPH_KEYS,
    "`[objectives]`": problems._OBJ_KEYS,
    "`[environment]`": problems._ENV_KEYS,
    "`[environment.agent]`": agent_mod._AGENT_KEYS,
    "A park (`parks = [{...}]`)": agent_mod._PARK_KEYS,
}


@pytest.mark.parametrize("heading", sorted(SECTIONS))
def test_every_accepted_key_is_documented_and_back(heading: str) -> None:
    assert documented_keys(heading) == set(SECTIONS[heading]), f"docs/problem-format.md, {heading}"


def toml_examples() -> list[str]:
    return [b for b in re.findall(r"```toml\n(.*?)```", TEXT, flags=re.S) if "[objectives]" in b]


def test_every_complete_example_loads(tmp_path: Path) -> None:
    examples = toml_examples()
    kinds = set()
    for i, block in enumerate(examples):
        path = tmp_path / f"example{i}.toml"
        path.write_text(block)
        kinds.add(load_problem_file(path).kind)
    assert kinds == {"reactive", "mixed", "agent"}


def test_the_python_fuel_example_builds_a_fuel_problem() -> None:
    block = re.search(r"## Fuel.*?```python\n(.*?)```", TEXT, flags=re.S)
    assert block is not None
    scope: dict = {}
    exec(compile(block.group(1), str(DOC), "exec"), scope)  # noqa: S102 - the documented example
    assert scope["problem"].system.kind == "fuel"


def test_an_undocumented_key_is_refused(tmp_path: Path) -> None:
    block = toml_examples()[-1].replace("max_iterations = 100", 'park = "above"')
    path = tmp_path / "bad.toml"
    path.write_text(block)
    with pytest.raises(ProblemError, match="unknown key 'park'"):
        load_problem_file(path)


def test_static_area_allows_walls_and_does_not_force_them(tmp_path: Path) -> None:
    """The mixed example's static area gives walls; a static area the optimum does not
    need (one move far from every useful route) gives none, as the page says."""
    from synthesis.pipeline import synthesize

    mixed = next(b for b in toml_examples() if 'kind = "mixed"' in b)
    path = tmp_path / "mixed.toml"
    path.write_text(mixed)
    assert synthesize(load_problem_file(path)).strategy.static_obstacles.any()
    path.write_text(re.sub(r"static = .*", "static = [[[2, 2], [2, 1]]]", mixed))
    test = synthesize(load_problem_file(path))
    assert not test.strategy.static_obstacles.any()
    assert test.strategy.blocked.any()  # the test is made of reactive restrictions instead


def test_agent_loop_progress_and_what_it_could_not_reach(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The documented agent example with a loop bound of one: the round is shown on
    standard error and the error names the places the agent could not block in time."""
    from experiments.cli.cli import main

    agent = next(b for b in toml_examples() if 'kind = "agent"' in b)
    path = tmp_path / "agent.toml"
    path.write_text(agent.replace("max_iterations = 100", "max_iterations = 1"))
    code = main(["synthesize", str(path)])
    out, err = capsys.readouterr()
    assert code == 3, err
    assert "agent loop 1/1: flow" in err
    error = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(error) == 1 and "cut set 1 blocks places [" in error[0] and "cannot reach them in time" in error[0]
