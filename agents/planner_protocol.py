"""The planner protocol's data: the messages FlowTest sends an outside planner, and its
answers read as data.

Every planner from outside FlowTest (``cmd:`` and ``python:``, :mod:`agents.external`;
docs/runtime.md) plays the same game as the built-in systems: the ``hello`` message's
``test`` (:func:`flowtest_env.runtime.describe`) holds the map with the static walls apart
from the moves and the system objective's automaton, and every ``step`` message says which
moves are restricted now and by what (``wall``, ``door``, ``agent``;
:func:`flowtest_env.runtime.restricted_moves`). :class:`Messages` builds them for one
environment.

An answer is an action name or a small index in range, nothing else
(:func:`parse_answer`): a line that is not one, a number too long to be an index, a digit
outside ASCII, ``NaN`` or a nesting too deep is "not an action", never an exception.
"""

from __future__ import annotations

import json
import math
import re
from typing import Any

import numpy as np

from flowtest_env.game import TestGame
from flowtest_env.runtime import describe, restricted_moves

from .base import PolicyError, action_mask_of, game_of, state_index

PROTOCOL = "flowtest-planner"
PROTOCOL_VERSION = 2
"""2: the walls apart from the moves (``test.system.walls``), the system objective's
automaton (``test.automaton``) and each step's ``restricted`` moves with their cause.
Version 1 clients keep working (the new fields are extra; ``moves`` lost only moves the
test never allowed)."""

DEFAULT_STEP_TIMEOUT = 10.0
"""Seconds a planner may take to answer one step (a ``cmd:`` planner's first answer
includes its start; a ``python:`` planner's ``reset`` and its factory are timed as one
step)."""

MAX_STEP_TIMEOUT = 3600.0
"""The longest step timeout accepted (seconds)."""

MAX_ANSWER = 1 << 16
"""The longest answer line read from a planner (bytes): a longer one fails its run."""

_INDEX = re.compile(r"[0-9]{1,6}")
"""An action index as text: ASCII digits, few of them."""


class PlannerError(RuntimeError):
    """A planner failed during a run: it crashed (raised, exited), hung past the step
    timeout, or answered something that is not an allowed action. The run is the
    system's failure; the message says what happened and at which step."""


def step_timeout(seconds: float | None) -> float:
    """The step timeout to use: ``seconds``, or :data:`DEFAULT_STEP_TIMEOUT`.

    Raises
    ------
    PolicyError
        Unless it is a number of seconds above 0 and at most :data:`MAX_STEP_TIMEOUT`.
    """
    if seconds is None:
        return DEFAULT_STEP_TIMEOUT
    try:
        value = float(seconds)
    except (TypeError, ValueError, OverflowError):
        raise PolicyError(f"the step timeout must be a number of seconds, not {seconds!r}") from None
    if not (math.isfinite(value) and 0 < value <= MAX_STEP_TIMEOUT):
        raise PolicyError(f"the step timeout must be above 0 and at most {MAX_STEP_TIMEOUT:g} seconds, not {seconds}")
    return value


def max_steps_of(env: Any) -> int | None:
    """The step budget of ``env`` (``None`` if it has none)."""
    for obj in (env, getattr(env, "unwrapped", None)):
        n = getattr(obj, "max_steps", None)
        if isinstance(n, int):
            return n
    return None


def describe_test(game: TestGame, max_steps: int | None) -> dict[str, Any]:
    """The public description of a test, as a system under test may know it (the
    ``hello`` message's ``test``; :func:`flowtest_env.runtime.describe`): never the hidden
    test objective or the restrictions."""
    return describe(game, max_steps)


def _run_of(env: Any) -> Any:
    for obj in (getattr(env, "unwrapped", None), env):
        run = getattr(obj, "run", None)
        if run is not None and hasattr(run, "system"):
            return run
    return None


class Messages:
    """The protocol's messages for one environment (``hello`` and ``step``)."""

    def __init__(self, env: Any) -> None:
        self.env = env
        self.game = game_of(env)
        self.test = describe_test(self.game, max_steps_of(env))
        self.count = 0

    def hello(self) -> dict[str, Any]:
        """The first message to a planner: the protocol, its version and the test."""
        return {"type": "hello", "protocol": PROTOCOL, "version": PROTOCOL_VERSION, "test": self.test}

    def step(self, observation: Any, info: dict[str, Any]) -> tuple[dict[str, Any], np.ndarray, int]:
        """``(message, mask, state index)`` of the situation now."""
        g = self.game
        mask = np.asarray(action_mask_of(observation, info), dtype=np.int8)
        run = _run_of(self.env)
        if run is not None:
            s, k = int(run.system), int(run.steps)
            agent_state = int(run.agent)
            restricted = restricted_moves(g, run)
        else:
            s, k, agent_state = state_index(g, info["system_state"]), self.count, -1
            restricted = _restricted_by_mask(g, s, mask)
        self.count = k + 1
        allowed = [int(a) for a in np.flatnonzero(mask)]
        place = g.agent_place[agent_state] if 0 <= agent_state < g.n_agent_states else -1
        msg = {
            "type": "step",
            "step": k,
            "state": g.state_json(s),
            "allowed": [g.action_name(s, a) for a in allowed],
            "to": [g.state_json(s if a == g.stay_action else int(g.succ_list[s][a])) for a in allowed],
            "mask": mask.tolist(),
            "restricted": restricted,
            "agent": None if place < 0 else _place_json(g, place),
        }
        return msg, mask, s


def _restricted_by_mask(game: TestGame, s: int, mask: np.ndarray) -> list[dict[str, Any]]:
    """The restricted moves out of ``s`` read from the mask alone (an env that shows no
    run): a static wall is a ``wall``, any other refusal a ``door``."""
    out = []
    for k in range(game.n_slots):
        if game.slot_list[s][k] >= 0 and not mask[k]:
            by = "wall" if game.static_bits[s] >> k & 1 else "door"
            out.append({"action": game.action_name(s, k), "to": game.state_json(game.succ_list[s][k]), "by": by})
    return out


def _place_json(game: TestGame, place: int) -> object:
    p = game.ts.places[place]
    return list(p) if isinstance(p, tuple) else p


# --------------------------------------------------------------------------- answers


class Shown:
    """An answer that is no action's kind (a list, a float, an object), kept as its
    shortened ``repr`` for the message that refuses it."""

    def __init__(self, text: str) -> None:
        self.text = text

    def __repr__(self) -> str:
        return self.text


def plain_answer(answer: Any) -> Any:
    """A ``python:`` planner's answer reduced to what :func:`parse_answer` reads (an
    ``int``, a short ``str``, ``{"action": ...}``) or a :class:`Shown` of it: small, and
    safe to send between processes."""
    if isinstance(answer, (bool, np.bool_)):
        return Shown(repr(bool(answer)))
    if isinstance(answer, (int, np.integer)):
        value = int(answer)
        return value if -(10**9) < value < 10**9 else Shown(f"an integer of {value.bit_length()} bits")
    if isinstance(answer, str):
        return answer[:200]
    if isinstance(answer, dict):
        return {"action": plain_answer(answer["action"])} if "action" in answer else {"keys": Shown(short(list(answer)))}
    return Shown(short(answer))


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not JSON")


def _small_int(text: str) -> int:
    if len(text) > 9:
        raise ValueError("too long for an action index")
    return int(text)


def decode_line(line: str) -> Any:
    """A planner's answer line as a value: JSON when it is a JSON string or object (numbers
    short, no ``NaN``), a small ASCII index, else the text itself (an action's bare name)."""
    text = line.strip()
    if _INDEX.fullmatch(text):
        return int(text)
    if text[:1] in ("{", '"'):
        try:
            return json.loads(text, parse_int=_small_int, parse_constant=_no_constant)
        except (ValueError, RecursionError):
            return text
    return text


def parse_answer(answer: Any, game: TestGame, state: int, mask: np.ndarray, step: int, hint: str = "") -> int:
    """The action index a planner's answer names: an index in range, an action's name
    (``"N"``, ``"stay"``, ``"-> d1"``, on graphs the state's name alone), or either as
    ``{"action": ...}``; a protocol line (``str`` or ``bytes``) is decoded first
    (:func:`decode_line`).

    Raises
    ------
    PlannerError
        If the answer names no action, or one the test does not allow now.
    """
    if isinstance(answer, bytes):
        answer = answer.decode("utf-8", "replace")
    raw = answer
    if isinstance(answer, str):
        answer = decode_line(answer)
    if isinstance(answer, dict):
        if "action" not in answer:
            raise PlannerError(f'step {step}: answered {short(raw)}, an object without "action"{hint}')
        answer = answer["action"]
    names = [game.action_name(state, a) for a in range(game.n_actions)]
    action: int | None = None
    if isinstance(answer, (int, np.integer)) and not isinstance(answer, (bool, np.bool_)):
        action = int(answer) if 0 <= int(answer) < game.n_actions else None
    elif isinstance(answer, str):
        word = answer.strip()
        if word in names:
            action = names.index(word)
        elif _INDEX.fullmatch(word) and int(word) < game.n_actions:
            action = int(word)
        elif not game.is_grid and f"-> {word}" in names:
            action = names.index(f"-> {word}")
    if action is None:
        raise PlannerError(
            f"step {step}: answered {short(raw)}, which is not an action (expected an index 0..{game.n_actions - 1} or one of: {', '.join(names)}){hint}"
        )
    if not mask[action]:
        allowed = ", ".join(names[a] for a in np.flatnonzero(mask))
        raise PlannerError(f"step {step}: chose {names[action]!r}, which the test does not allow now (allowed: {allowed})")
    return action


def short(x: Any, n: int = 80) -> str:
    """A short quotation of an answer: a line in quotes, a Python value as its ``repr``."""
    if not isinstance(x, str):
        try:
            text = repr(x)
        except Exception:  # a planner's object whose repr fails
            text = f"a {type(x).__name__}"
        return text if len(text) <= n else text[:n] + "..."
    text = x.strip()
    return repr(text if len(text) <= n else text[:n] + "...")
