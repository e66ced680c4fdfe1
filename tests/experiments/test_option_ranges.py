"""Every count a command runs for has a stated maximum (issue 43): ``flowtest evaluate
--episodes 100000000000000000000`` ran until stopped, keeping every run for the report; now a
value out of range is one ``error:`` line, before any work or file."""

from __future__ import annotations

import pytest

from experiments.cli.arguments import ArgumentParser
from experiments.cli.evaluate import add_arguments

MAX_EPISODES = 100_000


def _parser() -> ArgumentParser:
    p = ArgumentParser(prog="flowtest evaluate")
    add_arguments(p)
    return p


@pytest.mark.parametrize("value", ["100000000000000000000", str(MAX_EPISODES + 1), "0", "-1", "2.5", "1e3"])
def test_episodes_out_of_range_is_one_error_line(capsys: pytest.CaptureFixture[str], value: str) -> None:
    """Refused by the parser: before any test is built, any run played or any file written."""
    with pytest.raises(SystemExit) as stop:
        _parser().parse_args(["--env", "small-reactive", "--sut", "random", "--episodes", value, "--out", "report"])
    stdout, err = capsys.readouterr()
    assert stop.value.code == 2 and stdout == "" and err.count("\n") == 1, err
    assert err.startswith("error: flowtest evaluate: argument --episodes: expected a number of runs (1-100000)"), err


def test_the_largest_count_is_accepted_and_stated_in_the_help() -> None:
    from experiments.cli import evaluate

    assert evaluate.MAX_EPISODES == MAX_EPISODES
    args = _parser().parse_args(["--env", "x", "--sut", "random", "--episodes", str(MAX_EPISODES)])
    assert args.episodes == MAX_EPISODES
    assert "at most 100,000" in _parser().format_help()
