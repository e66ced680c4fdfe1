"""What a solver option's value must be, each rule with one reason text, shared by every door an
option comes through: the options of a Python call (:func:`synthesis.routing.options.check_options`),
a problem file (``time_limit`` in ``[environment]``, :mod:`synthesis.problems.files`) and the
command line (``flowtest synthesize --time-limit``, :mod:`experiments.cli.arguments`). The same
bad value gets the same reason wherever it is typed; only where it was typed differs.

The rules live here, below both the problem files and the routing model, so that each can use
them; which option follows which rule is the table of :mod:`synthesis.routing.options`.

Example
-------
>>> SECONDS.check(30, "option time_limit")
30
>>> SECONDS.reason(-1.5)
'must be a positive finite number of seconds, not -1.5'
>>> SECONDS.check(None, "option time_limit") is None  # optional: None means no limit
True
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np

from .errors import ProblemError
from .strategy import SETTINGS

T = TypeVar("T")

MAX_THREADS = 256
"""Most solver threads accepted (far above any machine FlowTest runs on)."""

MAX_SEED = 2**31 - 1
"""Largest solver random seed (HiGHS's and CP-SAT's seeds are 32-bit signed integers)."""


def shown(value: object, limit: int = 60) -> str:
    """``repr(value)`` cut to ``limit`` characters (a number of thousands of digits stays one
    short line in a message)."""
    text = repr(value)
    return text if len(text) <= limit else f"{text[: limit - 3]}... ({len(text)} characters)"


def _number(v: object) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _finite(v: object) -> bool:
    """A number finite as a float (an integer too large for one is not)."""
    try:
        return _number(v) and math.isfinite(v)  # type: ignore[arg-type]
    except OverflowError:
        return False


def _integer(v: object) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


@dataclass(frozen=True)
class Rule:
    """A kind of option value: ``what`` it must be, in words, and the test it must pass.

    ``optional``: ``None`` is accepted too (no limit, or: decided elsewhere). ``from_text`` turns
    the text of a command-line flag into a value (``float`` or ``int``) before the test.
    """

    what: str
    test: Callable[[Any], bool]
    optional: bool = False
    from_text: Callable[[str], Any] | None = None

    def reason(self, value: object) -> str | None:
        """Why ``value`` is refused, the same words through every door (``None``: accepted)."""
        if (value is None and self.optional) or (value is not None and self.test(value)):
            return None
        return f"must be {self.what}, not {shown(value)}"

    def error(self, value: object, where: str) -> ProblemError | None:
        """The error for ``value`` typed at ``where`` (``"option time_limit"``, ``"`time_limit` in
        [environment] (p.toml)"``), ``None`` if it is accepted."""
        why = self.reason(value)
        return None if why is None else ProblemError(f"{where} {why}")

    def check(self, value: T, where: str) -> T:
        """``value``, if accepted; raises :class:`ProblemError` naming ``where`` and the reason."""
        err = self.error(value, where)
        if err is not None:
            raise err
        return value

    def parse(self, text: str) -> Any:
        """The value a command-line flag's ``text`` gives, checked.

        Raises
        ------
        ValueError
            With the reason alone (the command line says which flag): for text that is no
            number as for a number the rule refuses.
        """
        convert = self.from_text or str
        try:
            value = convert(text)
        except ValueError:
            raise ValueError(f"must be {self.what}, not {text!r}") from None
        why = self.reason(value)
        if why is not None:
            raise ValueError(why)
        return value


@dataclass(frozen=True)
class Choice(Rule):
    """One of a few names (a backend, a mode). Its message names what is unknown first, the way
    a misspelled name is reported everywhere: ``unknown solver backend 'gurobi' (option
    backend); expected one of auto, highs, cpsat``."""

    noun: str = ""
    values: Sequence[str] = ()

    def reason(self, value: object) -> str | None:
        if (value is None and self.optional) or (isinstance(value, str) and value in self.values):
            return None
        return f"unknown {self.noun} {shown(value)}; expected one of {', '.join(self.values)}"

    def error(self, value: object, where: str) -> ProblemError | None:
        why = self.reason(value)
        if why is None:
            return None
        head, _, tail = why.partition(";")
        return ProblemError(f"{head} ({where});{tail}")


def choice(noun: str, values: Sequence[str], optional: bool = False) -> Choice:
    """The rule of an option that takes one of ``values`` (``noun`` names it in the message;
    ``optional``: ``None`` is accepted too)."""
    names = tuple(values)
    return Choice(f"one of {', '.join(names)}", lambda v: v in names, optional, None, noun, names)


SECONDS = Rule("a positive finite number of seconds", lambda v: _finite(v) and v > 0, True, float)
"""Wall-clock seconds (``time_limit``, ``after_first``); ``None``: no limit."""

WORK = Rule("a positive finite number", lambda v: _finite(v) and v > 0, True, float)
"""A deterministic work budget (CP-SAT's deterministic seconds, ``work_limit``); ``None``: no limit."""

GAP = Rule("a number in [0, 1)", lambda v: _finite(v) and 0.0 <= v < 1.0, False, float)
"""A relative MIP gap (``mip_rel_gap``); 0 proves optimality."""

THREADS = Rule(f"an integer from 1 to {MAX_THREADS}", lambda v: _integer(v) and 1 <= v <= MAX_THREADS, True, int)
"""Solver threads; ``None``: decided elsewhere (one, from :func:`synthesis.pipeline.synthesize`)."""

COUNT = Rule("a positive integer", lambda v: _integer(v) and v >= 1, True, int)
"""A count bound (``node_limit``, ``agent_iterations``, ``max_graph_edges``); ``None``: no bound."""

SEED = Rule(f"an integer from 0 to {MAX_SEED}", lambda v: _integer(v) and 0 <= v <= MAX_SEED, False, int)
"""A solver's random seed."""

FLAG = Rule("true or false", lambda v: isinstance(v, (bool, np.bool_)))
"""A switch."""

SETTING = choice("obstacle setting", SETTINGS, optional=True)
"""How reactive obstacles are shown (``setting``); ``None``: the problem's, else instantaneous."""

CALLBACK = Rule("a function of one string or None", callable, True)
"""A progress callback (``progress``)."""


def instance_of(kind: type, what: str, optional: bool = True) -> Rule:
    """The rule of an option holding an object of ``kind`` (``what`` names it in the message)."""
    return Rule(what, lambda v: isinstance(v, kind), optional)
