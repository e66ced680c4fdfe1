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
==========================  ============================================================

Each policy module exposes a factory ``(env, argument) -> Policy`` and knows nothing of
this list; :data:`FACTORIES` names them all, so adding a policy is one entry here.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Any

from . import gr1_sut, ppo, scripted
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
}
"""Every policy by the prefix of its name (``prefix`` or ``prefix:ARG``)."""

_NAME = re.compile(r"^([a-z0-9_-]+)(?::(.*))?$")


def policy_names() -> list[str]:
    """The name prefixes (for help texts and errors)."""
    return sorted(FACTORIES)


def make_policy(name: str, env: Any) -> Policy:
    """Build the policy called ``name`` for ``env`` (see the module docstring).

    Raises
    ------
    PolicyError
        On an unknown name or an env the policy cannot play.
    """
    m = _NAME.match(name.strip())
    if not m or m.group(1) not in FACTORIES:
        raise PolicyError(f"unknown policy {name!r}; known: random, scripted:<name>, gr1, ppo:PATH")
    policy = FACTORIES[m.group(1)](env, m.group(2) or "")
    policy.name = name
    return policy
