"""The systems a benchmark scores besides its baselines, as ``--sut`` names them: one system
may have several seeds (one model or policy each), scored with the same seed-and-test
statistics as the trained baselines (docs/benchmark-protocol.md, *Your own systems*).

:func:`parse_systems` reads the ``--sut`` entries into :class:`SystemSpec` s:

* ``ppo:runs/*.zip``: a glob, one seed per matching file (sorted); the system is named
  by the pattern as written;
* ``python:MODULE:NAME@GLOB``: the loader of a batched policy (:mod:`agents.batched`)
  called with each matching file, one seed each: members
  ``python:MODULE:NAME('runs/seed0.pt')``, ...;
* ``NAME=SPEC``: the system is called ``NAME``; repeating ``NAME=`` with other specs adds
  one seed per entry (``mine=python:m:load(0) mine=python:m:load(1)``).

Any other entry is one system with one run, as before. :func:`member_policies` gives a
member's batched policies (greedy and sampled) and the env options its observations need,
or ``None`` when it plays through the single env.
"""

from __future__ import annotations

import glob
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from synthesis.model.errors import ProblemError

GLOB_CHARS = "*?["
"""Characters that make a ``ppo:`` path or an ``@`` pattern a glob."""

_NAMED = re.compile(r"^([A-Za-z][A-Za-z0-9_.+-]*)=(.+)$", re.DOTALL)
_PYTHON_GLOB = re.compile(r"^python:([^()\"'@]+:[A-Za-z_][A-Za-z0-9_.]*)@(.+)$", re.DOTALL)


@dataclass(frozen=True)
class SystemSpec:
    """One scored system: its ``name`` in the table, its ``kind`` (``floor``, ``reference``,
    ``system``), its ``members`` (one SUT name per seed, in order) and whether they are
    ``seeded`` (a glob or a ``NAME=`` system: seeds ``0..N-1``; otherwise one run, seed
    ``None``)."""

    name: str
    kind: str
    members: tuple[str, ...]
    seeded: bool = False

    @property
    def seeds(self) -> list[int | None]:
        """The seed of each member's run."""
        return list(range(len(self.members))) if self.seeded else [None] * len(self.members)


def has_glob(text: str) -> bool:
    return any(c in text for c in GLOB_CHARS)


def expand(spec: str) -> tuple[list[str], bool]:
    """The members of one ``--sut`` spec (without a ``NAME=``) and whether it was a pattern.

    Raises
    ------
    ProblemError
        If a pattern matches no file.
    """
    m = _PYTHON_GLOB.match(spec)
    if m is not None:
        files = _matches(m.group(2), spec)
        return [f"python:{m.group(1)}({f!r})" for f in files], True
    if spec.startswith("ppo:") and has_glob(spec[4:]) and not Path(spec[4:]).exists():
        return [f"ppo:{f}" for f in _matches(spec[4:], spec)], True
    return [spec], False


def _matches(pattern: str, spec: str) -> list[str]:
    files = sorted(f for f in glob.glob(pattern) if Path(f).is_file())
    if not files:
        raise ProblemError(f"--sut {spec}: the pattern {pattern!r} matches no file (from {Path.cwd()})")
    return files


def parse_systems(suts: Sequence[str], reserved: Sequence[str]) -> list[SystemSpec]:
    """The ``--sut`` entries as systems (module docstring), in the order first given; an
    entry given twice is scored once. ``reserved``: the names a ``NAME=`` may not take (the
    floor, the references, the baselines).

    Example::

        >>> [s.members for s in parse_systems(["mine=scripted:greedy", "mine=scripted:committed", "gr1"], [])]
        [('scripted:greedy', 'scripted:committed'), ('gr1',)]

    Raises
    ------
    ProblemError
        On a reserved or repeated name, or a pattern that matches no file.
    """
    named: dict[str, list[str]] = {}
    order: list[tuple[str, list[str], bool]] = []
    plain: set[str] = set()
    for entry in dict.fromkeys(suts):
        m = _NAMED.match(entry)
        if m is None:
            members, seeded = expand(entry)
            if entry in named:
                raise ProblemError(f"--sut {entry}: the name of a NAME= system given as a system itself")
            plain.add(entry)
            order.append((entry, members, seeded))
            continue
        name, spec = m.group(1), m.group(2)
        if name in reserved:
            raise ProblemError(f"--sut {entry}: {name!r} names a system the benchmark scores already; choose another NAME")
        if name in plain:
            raise ProblemError(f"--sut {entry}: {name!r} is also given as a system of its own")
        if name not in named:
            named[name] = []
            order.append((name, named[name], True))
        named[name].extend(expand(spec)[0])
    return [SystemSpec(name, "system", tuple(members), seeded) for name, members, seeded in order]


@dataclass
class MemberPolicies:
    """A member's batched policies (``{"greedy": ..., "sampled": ...}``, either may be
    missing) and the env options of the batch they play (``memory``, ``obs_kind``)."""

    policies: dict[str, Any]
    options: dict[str, Any] = field(default_factory=dict)


def member_policies(sut: str, games: Sequence[Any]) -> MemberPolicies | None:
    """The batched policies of a system that has them, or ``None`` when it plays through
    the single env: ``random`` (sampled only), a saved model ``ppo:PATH`` (native or
    stable-baselines3 with a flat observation; greedy and sampled), and a ``python:`` loader
    marked ``batched = True`` (:mod:`agents.batched`; greedy and sampled through its one
    ``act``). ``games``: tests of the pool (where a stable-baselines3 model's memory reads
    the SUT's place).

    Raises
    ------
    ProblemError
        If the model or the policy cannot be loaded, or is not a batched policy.
    """
    from agents.base import PolicyError
    from flowtest_env.scoring import random_policy

    if sut == "random":  # the floor (config.RANDOM)
        return MemberPolicies({"sampled": random_policy()})
    try:
        if sut.startswith("ppo:"):
            return _model_policies(sut[4:], games)
        if sut.startswith("python:"):
            policy = load_batched(sut[len("python:") :])
            if policy is None:
                return None
            from agents.batched import ModePolicy, declared_options

            return MemberPolicies({"greedy": ModePolicy(policy, True), "sampled": ModePolicy(policy, False)}, declared_options(policy))
    except PolicyError as exc:
        raise ProblemError(f"--sut {sut}: {exc}") from None
    return None


def load_batched(spec: str) -> Any:
    """The batched policy ``python:SPEC`` names (its loader called with the spec's
    arguments), or ``None`` when the object is not marked ``batched = True`` (a planner).

    Raises
    ------
    agents.base.PolicyError
        If the loader raises or returns no batched policy.
    """
    from agents.batched import check_batched, is_batched
    from agents.external import python_call

    obj, args, kwargs = python_call(spec)
    if not is_batched(obj):
        return None
    from agents.base import PolicyError

    try:
        policy = obj(*args, **kwargs)
    except Exception as exc:  # noqa: BLE001 - the user's loader failing is their input's problem
        raise PolicyError(f"its loader raised {type(exc).__name__}: {' '.join(str(exc).split())[:300]}") from None
    check_batched(policy, "its loader")
    return policy


def _model_policies(path: str, games: Sequence[Any]) -> MemberPolicies | None:
    """A saved model's batched policies: a native checkpoint's (its memory kept by the
    actor), or a stable-baselines3 model's (:class:`agents.ppo.ModelBatchPolicy`) when it
    reads flat observations; ``None`` for one that plays through the single env."""
    from agents.checkpoint import is_native_checkpoint
    from agents.ppo import ModelBatchPolicy, load_model, model_where

    model = load_model(path)
    obs = dict(getattr(model, "flowtest_obs", None) or {"obs_kind": "flat", "pad_to": 8})
    if is_native_checkpoint(path):
        return MemberPolicies({"greedy": model.batch_policy(True), "sampled": model.batch_policy(False)}, {"obs_kind": obs["obs_kind"]})
    if obs.get("obs_kind", "flat") != "flat":
        return None  # PPOPolicy encodes each test with the model's own encoder, through the single env
    where = model_where(model, games, str(getattr(model, "flowtest_memory", "none")))
    return MemberPolicies({"greedy": ModelBatchPolicy(model, where, True), "sampled": ModelBatchPolicy(model, where, False)})


def check_systems(specs: Sequence[SystemSpec]) -> None:
    """Check every member before any work: a known name, a ``python:`` module and name that
    exist (a batched policy's loader is called once, so a missing file is said now), a
    stable-baselines3 zip trusted.

    Raises
    ------
    ProblemError
        Naming the member.
    """
    from agents.base import PolicyError
    from agents.ppo import check_trusted
    from experiments.evaluation import check_sut_names

    members = [m for s in specs for m in s.members]
    check_sut_names(members)
    for sut in members:
        if sut.startswith("ppo:"):
            check_trusted(sut[4:])  # a pickled model is refused before any work
        elif sut.startswith("python:"):
            try:
                load_batched(sut[len("python:") :])
            except PolicyError as exc:
                raise ProblemError(f"--sut {sut}: {exc}") from None
