"""Argument parsing shared by every command: the parser's error contract and value types.

A usage error is one ``error: ...`` line on stderr and exit code 2
(:data:`~experiments.cli.exits.EXIT_INVALID`); argparse would print its usage block first.
The types below reject a bad value with a message that says what was expected.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from typing import Any, NoReturn

from flowtest_env.validation import positive_int as checked_positive_int
from synthesis.model.option_rules import Rule

from .exits import EXIT_INVALID
from .exits import error as error_line


class ArgumentParser(argparse.ArgumentParser):
    """argparse with FlowTest's error contract: a usage error is one ``error: ...`` line
    on stderr and exit code 2 (argparse would print the usage block first)."""

    def error(self, message: str) -> NoReturn:
        error_line(f"{self.prog}: {message} (see `{self.prog} --help`)")
        raise SystemExit(EXIT_INVALID)


def positive_seconds(text: str) -> float:
    """An argparse type: a finite number of seconds > 0 (time limits)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of seconds, got {text!r}") from None
    if not math.isfinite(v) or v <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive number of seconds, got {text!r}")
    return v


def _integer(text: str, expected: str) -> int:
    """``text`` as an integer; an argparse error that says ``expected`` otherwise."""
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}") from None


def seconds_at_most(maximum: float) -> Callable[[str], float]:
    """An argparse type: a number of seconds > 0 and at most ``maximum`` (timeouts: a
    larger one would overflow the clocks that wait for it).

    >>> seconds_at_most(60.0)("2.5")
    2.5
    """

    def parse(text: str) -> float:
        v = positive_seconds(text)
        if v > maximum:
            raise argparse.ArgumentTypeError(f"expected at most {maximum:g} seconds, got {text!r}")
        return v

    parse.__name__ = f"seconds_at_most({maximum:g})"
    return parse


def int_between(low: int, high: int, what: str) -> Callable[[str], int]:
    """An argparse type: an integer from ``low`` to ``high`` (``what`` names it in the
    message: ``a port``).

    >>> int_between(0, 65535, "a port")("8765")
    8765
    """

    def parse(text: str) -> int:
        v = _integer(text, f"{what} ({low}-{high})")
        if not low <= v <= high:
            raise argparse.ArgumentTypeError(f"expected {what} ({low}-{high}), got {text!r}")
        return v

    parse.__name__ = f"int_between({low}, {high})"
    return parse


def nonnegative_int(text: str) -> int:
    """An argparse type: an integer >= 0 (seeds)."""
    if (v := _integer(text, "a non-negative integer")) < 0:
        raise argparse.ArgumentTypeError(f"expected a non-negative integer, got {text!r}")
    return v


def positive_int(text: str) -> int:
    """An argparse type: an integer >= 1 (episodes, steps, threads), by the rule the envs
    check their counts with (:func:`flowtest_env.validation.positive_int`)."""
    try:
        return checked_positive_int("value", _integer(text, "a positive integer"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None


def option_type(rule: Rule) -> Callable[[str], Any]:
    """An argparse type for a solver option's flag, by the option's rule
    (:mod:`synthesis.model.option_rules`): ``--time-limit -1`` is refused with the reason the
    option ``time_limit=-1`` gets from Python and from a problem file.

    >>> from synthesis.model.option_rules import SECONDS
    >>> option_type(SECONDS)("2.5")
    2.5
    """

    def parse(text: str) -> Any:
        try:
            return rule.parse(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    parse.__name__ = f"option_type({rule.what})"
    return parse


def add_trust_model(p: argparse.ArgumentParser, help_text: str) -> None:
    """Declare ``--trust-model`` (loading stable-baselines3 zips, which unpickles them), with
    what it lets the command load (``help_text``); :func:`apply_trust_model` acts on it."""
    p.add_argument("--trust-model", action="store_true", help=help_text)


def apply_trust_model(args: argparse.Namespace) -> None:
    """With ``--trust-model``, let this process load stable-baselines3 zips
    (:func:`agents.checkpoint.trust_pickled_models`); before any model is loaded."""
    if args.trust_model:
        from agents.checkpoint import trust_pickled_models

        trust_pickled_models(True)
