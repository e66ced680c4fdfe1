"""Systems under test by name: the one module that knows every policy.

Policies are named by plain strings on the command line (:func:`make_policy`):

==========================  ============================================================
``random``                  uniform over the legal actions (seeded)
``scripted:replanner``      the correct scripted SUT (:mod:`agents.scripted`)
``scripted:committed``      faulty: plans once, never replans
``scripted:fuel-blind``     faulty: ignores fuel, safety and its own sub-goals
``scripted:greedy``         faulty: one-step greedy, can walk into dead ends
``gr1``                     GR(1)-synthesized controller (:mod:`agents.gr1_sut`)
``ppo:PATH``                a saved stable-baselines3 (Maskable)PPO model
``python:MODULE:NAME``      your planner in Python: a function ``act(observation, mask)``
                            or a factory of planners (:mod:`agents.external`);
                            ``python:MODULE:NAME(ARGS)`` calls the factory with literal ARGS
``cmd:COMMAND``             your planner as a process in any language, over JSON lines on
                            its standard input and output (:mod:`agents.external`)
==========================  ============================================================

Each policy module exposes a factory ``(env, argument) -> Policy`` and knows nothing of
this list; :data:`FACTORIES` names them all, so adding a policy is one entry here.
:func:`make_policy` also takes a Python object instead of a name: a
:class:`~agents.base.Policy` is used as it is, any other callable or planner object as a
``python:`` planner (:func:`agents.external.planner_policy`).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Any

from . import external, gr1_sut, ppo, scripted
from .base import Policy, PolicyError, RandomPolicy

PolicyFactory = Callable[[Any, str], Policy]
"""Builds a policy for an env from the argument after ``prefix:`` (``""`` if none)."""


def make_random(env: Any, arg: str) -> Policy:
    """``random``: uniform over the legal actions (its seed comes with ``reset``)."""
    return RandomPolicy()


FACTORIES: dict[str, PolicyFactory] = {
    "random": make_random,
    "scripted": scripted.make_scripted,
    "gr1": gr1_sut.make_gr1,
    "ppo": ppo.make_ppo,
    "python": external.make_python,
    "cmd": external.make_command,
}
"""Every policy by the prefix of its name (``prefix`` or ``prefix:ARG``)."""

TIMED_FACTORIES: dict[str, Callable[[Any, str, float | None], Policy]] = {
    "python": external.make_python,
    "cmd": external.make_command,
}
"""The planners from outside FlowTest, whose answers are timed (``step_timeout``)."""

_NAME = re.compile(r"^([a-z0-9_-]+)(?::(.*))?$", re.DOTALL)

KNOWN = "random, scripted:<name>, gr1, ppo:PATH, python:MODULE:NAME[(ARGS)], cmd:COMMAND"
"""The names, for error messages."""


def policy_names() -> list[str]:
    """The name prefixes (for help texts and errors)."""
    return sorted(FACTORIES)


def make_policy(name: str | Any, env: Any, step_timeout: float | None = None) -> Policy:
    """Build the policy called ``name`` for ``env`` (see the module docstring).

    ``name`` may also be a Python object: a :class:`~agents.base.Policy` (returned as it
    is) or a planner (a function ``act(observation, mask)``, a factory or a planner
    object, :func:`agents.external.planner_policy`). ``step_timeout`` bounds each exchange
    with a planner from outside FlowTest, ``cmd:`` or ``python:`` (seconds; default
    :data:`agents.external.DEFAULT_STEP_TIMEOUT`, at most :data:`agents.external.MAX_STEP_TIMEOUT`):
    ``make_policy("cmd:python3 planner.py", env, step_timeout=2.0)``.

    Raises
    ------
    PolicyError
        On an unknown name, a missing module, attribute or program, or an env the policy
        cannot play.

    Examples
    --------
    >>> import gymnasium as gym
    >>> import flowtest_env
    >>> from agents.registry import make_policy
    >>> env = gym.make("FlowTest-SmallReactive-v0")
    >>> policy = make_policy("scripted:replanner", env)
    >>> obs, info = env.reset(seed=0)
    >>> policy.reset(0)
    >>> done = False
    >>> while not done:
    ...     obs, reward, terminated, truncated, info = env.step(policy.act(obs, info))
    ...     done = terminated or truncated
    >>> info["verdict"]
    {'system_objective': 'met', 'test_objective_realized': True, 'restrictions': 1, 'blocked_attempts': 0, 'steps': 5}
    """
    if not isinstance(name, str):
        if isinstance(name, Policy):
            return name
        if callable(name) or callable(getattr(name, "act", None)):
            return external.planner_policy(name, env, step_timeout=step_timeout)
        raise PolicyError(f"a system under test is a name, a Policy or a planner, not a {type(name).__name__}")
    m = _NAME.match(name.strip())
    if not m or m.group(1) not in FACTORIES:
        raise PolicyError(f"unknown policy {name!r}; known: {KNOWN}")
    if m.group(1) in TIMED_FACTORIES:
        policy: Policy = TIMED_FACTORIES[m.group(1)](env, m.group(2) or "", step_timeout)
    else:
        policy = FACTORIES[m.group(1)](env, m.group(2) or "")
    policy.name = name
    return policy
