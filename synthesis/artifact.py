"""The synthesized-test artifact: a versioned JSON file that environments load.

It holds everything needed to *run* a test without solving anything: the transition
system with labels, the automata tables (to track histories), the restrictions, the
test agent's strategy table, and the synthesis summary (the JSON of
``flowtest synthesize``). Loading gives a :class:`TestArtifact`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .automata import DBA
from .errors import ProblemError
from .strategy import TestStrategy
from .systems import TransitionSystem

FORMAT = "flowtest-test"
VERSION = 1


def dba_to_dict(dba: DBA) -> dict:
    return {
        "delta": dba.delta.tolist(),
        "initial": dba.initial,
        "accepting": dba.accepting.astype(int).tolist(),
        "names": list(dba.names),
        "components": None if dba.components is None else dba.components.tolist(),
    }


def dba_from_dict(d: dict, letters: tuple[frozenset[str], ...]) -> DBA:
    comps = d.get("components")
    return DBA(
        delta=np.asarray(d["delta"], dtype=np.int32).reshape(-1, len(letters)),
        initial=int(d["initial"]),
        accepting=np.asarray(d["accepting"], dtype=bool).reshape(len(d["delta"]), -1),
        letters=letters,
        names=list(d["names"]),
        components=None if comps is None else np.asarray(comps, dtype=np.int32),
    )


@dataclass
class TestArtifact:
    """A loaded synthesized test.

    Attributes
    ----------
    name, kind
        Problem name and environment kind (``static``/``reactive``/``mixed``/``agent``).
    system
        The transition system.
    letters
        The automata's alphabet (labels).
    system_automaton, test_automaton, histories
        B_sys, B_test and B_pi (``histories.components[h] = (q_sys, q_test)``).
    strategy
        The restrictions per history.
    summary
        The ``flowtest synthesize --json`` object.
    agent
        The test agent (its cells, parks and strategy table), agent problems only.
    objectives
        ``{"system": ..., "test": ...}`` formula texts.
    """

    __test__ = False

    name: str
    kind: str
    system: TransitionSystem
    letters: tuple[frozenset[str], ...]
    system_automaton: DBA
    test_automaton: DBA
    histories: DBA
    strategy: TestStrategy
    summary: dict
    objectives: dict
    agent: dict | None = None
    extras: dict = field(default_factory=dict)

    def initial_history(self) -> int:
        """The history after reading ``L(s0)``."""
        ts = self.system
        return self.step_history(self.histories.initial, ts.initial)

    def step_history(self, history: int, state: int) -> int:
        """The history after entering ``state``."""
        return int(self.histories.delta[history, self._letter[state]])

    def __post_init__(self) -> None:
        self._letter = self.system.letter_of_state(self.letters)

    def to_dict(self) -> dict:
        return {
            "format": FORMAT,
            "version": VERSION,
            "name": self.name,
            "kind": self.kind,
            "objectives": self.objectives,
            "system": self.system.to_dict(),
            "letters": [sorted(a) for a in self.letters],
            "automata": {
                "system": dba_to_dict(self.system_automaton),
                "test": dba_to_dict(self.test_automaton),
                "histories": dba_to_dict(self.histories),
            },
            "strategy": self.strategy.to_dict(),
            "agent": self.agent,
            "summary": self.summary,
            "extras": self.extras,
        }

    @classmethod
    def from_dict(cls, d: dict, source: str = "<artifact>") -> "TestArtifact":
        if d.get("format") != FORMAT:
            raise ProblemError(f"{source} is not a FlowTest test artifact (format {d.get('format')!r})")
        if d.get("version") != VERSION:
            raise ProblemError(f"{source} has artifact version {d.get('version')}, this FlowTest reads {VERSION}")
        letters = tuple(frozenset(a) for a in d["letters"])
        a = d["automata"]
        return cls(
            name=d["name"],
            kind=d["kind"],
            system=TransitionSystem.from_dict(d["system"]),
            letters=letters,
            system_automaton=dba_from_dict(a["system"], letters),
            test_automaton=dba_from_dict(a["test"], letters),
            histories=dba_from_dict(a["histories"], letters),
            strategy=TestStrategy.from_dict(d["strategy"]),
            summary=d["summary"],
            objectives=d["objectives"],
            agent=d.get("agent"),
            extras=d.get("extras", {}),
        )

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), separators=(",", ":")))

    @classmethod
    def load(cls, path: str | Path) -> "TestArtifact":
        p = Path(path)
        try:
            data = json.loads(p.read_text())
        except OSError as exc:
            raise ProblemError(f"cannot read artifact {str(p)!r}: {exc.strerror or exc}") from None
        except json.JSONDecodeError as exc:
            raise ProblemError(f"{p}: invalid JSON: {exc}") from None
        return cls.from_dict(data, str(p))


def artifact_of(test: Any, summary: dict) -> TestArtifact:
    """The artifact of a :class:`~synthesis.pipeline.SynthesizedTest` and its summary."""
    p = test.problem
    spec = test.spec
    return TestArtifact(
        name=p.name,
        kind=p.kind,
        system=p.system,
        letters=spec.dba.letters,
        system_automaton=spec.sys,
        test_automaton=spec.test,
        histories=spec.dba,
        strategy=test.strategy,
        summary=summary,
        objectives={"system": p.system_objective.text, "test": p.test_objective.text},
        agent=None if test.agent is None else test.agent.to_dict(),
        extras={"history_descriptions": [spec.describe(h) for h in range(spec.dba.n_states)]},
    )
