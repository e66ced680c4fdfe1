"""The synthesized-test artifact: a versioned JSON file that environments load.

It holds everything needed to *run* a test without solving anything: the transition
system with labels, the automata tables (to track histories), the restrictions, the
test agent's strategy table, and the synthesis summary (the JSON of
``flowtest synthesize``). Loading gives a :class:`TestArtifact`.

An artifact cannot lie: loading checks every field against the schema
(:mod:`synthesis.artifacts.schema`), then :func:`verify_artifact` checks its meaning: the
``source`` hash of what it was synthesized from (system, objectives, kind) matches its
content, its automata are those of its objectives, and its restrictions pass the
independent checks of :mod:`synthesis.checks.verify` on its own product graphs (bypass flow 0,
the flow of its summary, feasibility). Any failure is a :class:`ProblemError` that names
what is wrong; an edited test never runs.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..checks.verify import check_test
from ..graphs.automata import DBA, specification_product
from ..graphs.products import build_products
from ..model.errors import ProblemError
from ..model.specs import parse_objective
from ..model.strategy import TestStrategy
from ..model.systems import TransitionSystem
from ..pipeline import SynthesizedTest
from ..problems.files import read_limited
from ..problems.problem import Problem
from .schema import validate_artifact

FORMAT = "flowtest-test"
VERSION = 1


def source_hash(system: dict[str, Any], objectives: dict[str, Any], kind: str) -> str:
    """SHA-256 of what a test is synthesized from: the transition system (as the artifact
    writes it), the two objective texts and the environment kind, as canonical JSON."""
    doc = {"format": FORMAT, "system": system, "objectives": {"system": objectives["system"], "test": objectives["test"]},
           "kind": kind}
    text = json.dumps(doc, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    return hashlib.sha256(text.encode("ascii")).hexdigest()


def problem_source_hash(problem: Problem) -> str:
    """:func:`source_hash` of a :class:`~synthesis.problems.problem.Problem` (before synthesis)."""
    return source_hash(problem.system.to_dict(),
                       {"system": problem.system_objective.text, "test": problem.test_objective.text}, problem.kind)


def dba_to_dict(dba: DBA) -> dict[str, Any]:
    return {
        "delta": dba.delta.tolist(),
        "initial": dba.initial,
        "accepting": dba.accepting.astype(int).tolist(),
        "names": list(dba.names),
        "components": None if dba.components is None else dba.components.tolist(),
    }


def dba_from_dict(d: dict[str, Any], letters: tuple[frozenset[str], ...]) -> DBA:
    comps = d.get("components")
    return DBA(
        delta=np.asarray(d["delta"], dtype=np.int32).reshape(-1, len(letters)),
        initial=int(d["initial"]),
        accepting=np.asarray(d["accepting"], dtype=bool).reshape(len(d["delta"]), -1),
        letters=letters,
        names=list(d["names"]),
        components=None if comps is None else np.asarray(comps, dtype=np.int32),
    )


@dataclass(frozen=True)
class TestArtifact:
    """A loaded synthesized test (immutable: a changed test is a new value).

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
    summary: dict[str, Any]
    objectives: dict[str, Any]
    agent: dict[str, Any] | None = None
    extras: dict[str, Any] = field(default_factory=dict)
    source: str = ""  # source_hash of what it was synthesized from
    _letter: np.ndarray = field(init=False, repr=False, compare=False)  # letter index of each state

    def initial_history(self) -> int:
        """The history after reading ``L(s0)``."""
        ts = self.system
        return self.step_history(self.histories.initial, ts.initial)

    def step_history(self, history: int, state: int) -> int:
        """The history after entering ``state``."""
        return int(self.histories.delta[history, self._letter[state]])

    def __post_init__(self) -> None:
        # a derived lookup table, not a field: computed once from the frozen fields
        object.__setattr__(self, "_letter", self.system.letter_of_state(self.letters))

    def to_dict(self) -> dict[str, Any]:
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
            "source": {"sha256": self.source or source_hash(self.system.to_dict(), self.objectives, self.kind)},
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any], source: str = "<artifact>", verify: bool = True) -> TestArtifact:
        """Build an artifact from its plain data, checked first (see the module docstring).

        Raises
        ------
        ProblemError
            Naming the field or the check that fails. ``verify=False`` skips the
            checks of meaning (:func:`verify_artifact`), never the schema.
        """
        validate_artifact(d, source, FORMAT, VERSION)
        try:
            letters = tuple(frozenset(a) for a in d["letters"])
            a = d["automata"]
            art = cls(
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
                source=d["source"]["sha256"],
            )
        except (KeyError, IndexError, TypeError, ValueError, AttributeError) as exc:
            # the schema should have said it; never let a raw error reach a user
            raise ProblemError(f"artifact {source} is malformed ({type(exc).__name__}: {exc})") from None
        if verify:
            verify_artifact(art, source)
        return art

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), separators=(",", ":")))

    @classmethod
    def load(cls, path: str | Path, verify: bool = True) -> TestArtifact:
        """Read and check an artifact file (see :meth:`from_dict`)."""
        p = Path(path)
        raw = read_limited(p, "artifact")
        try:
            data = json.loads(raw.decode("utf-8"))
        except UnicodeDecodeError:
            raise ProblemError(f"artifact {str(p)!r} is not UTF-8 text") from None
        except json.JSONDecodeError as exc:
            raise ProblemError(f"{p}: invalid JSON: {exc}") from None
        except RecursionError:
            raise ProblemError(f"{p}: invalid JSON: nested too deeply") from None
        return cls.from_dict(data, str(p), verify)


def _same_dba(a: DBA, b: DBA) -> bool:
    return (
        a.initial == b.initial
        and a.delta.shape == b.delta.shape
        and bool(np.array_equal(a.delta, b.delta))
        and a.accepting.shape == b.accepting.shape
        and bool(np.array_equal(a.accepting, b.accepting))
        and (
            (a.components is None and b.components is None)
            or (a.components is not None and b.components is not None and bool(np.array_equal(a.components, b.components)))
        )
    )


def verify_artifact(
    art: TestArtifact, source: str = "<artifact>", expected_source: str | None = None, restrictions: bool = True
) -> None:
    """Check what an artifact means against what it claims (cheap: graph searches and max flows).

    * its ``source`` hash equals the hash of its own system, objectives and kind (and
      ``expected_source`` when given: a cache entry must be the problem asked for);
    * its alphabet is its system's labels and its automata are those of its objectives;
    * its restrictions pass :func:`synthesis.checks.verify.check_test` on its own product
      graphs: bypass flow 0, the flow its summary states, no history's entry trapped
      (skipped with ``restrictions=False``: for files whose every byte is already known
      good, the shipped artifacts, so that ``gym.make`` needs no graph library).

    Raises
    ------
    ProblemError
        Naming the check that fails (the artifact was edited or made for another problem).
    """
    where = f"artifact {source}"
    own = source_hash(art.system.to_dict(), art.objectives, art.kind)
    if art.source != own:
        raise ProblemError(f"{where}: its system, objectives or kind do not match its source hash (the file was edited)")
    if expected_source is not None and art.source != expected_source:
        raise ProblemError(f"{where} was synthesized from another problem than the one asked for (source hash mismatch)")
    if art.letters != art.system.letters():
        raise ProblemError(f"{where}: field letters is not the alphabet of its system's labels")
    try:
        spec = specification_product(
            parse_objective(art.objectives["system"], "system"), parse_objective(art.objectives["test"], "test"), art.letters
        )
    except ProblemError as exc:
        raise ProblemError(f"{where}: field objectives: {exc}") from None
    for field_name, mine, derived in (("system", art.system_automaton, spec.sys), ("test", art.test_automaton, spec.test),
                                      ("histories", art.histories, spec.dba)):
        if not _same_dba(mine, derived):
            raise ProblemError(f"{where}: field automata.{field_name} is not the automaton of its objectives "
                               "(edited, or another problem's automata)")
    if not restrictions:
        return
    report = check_test(build_products(art.system, spec), art.strategy, int(art.summary["flow"]), raise_on_failure=False)
    if not report.ok:
        raise ProblemError(f"{where}: its restrictions fail the independent check: " + "; ".join(report.problems()))


def artifact_of(test: SynthesizedTest, summary: dict[str, Any], extras: Mapping[str, Any] | None = None) -> TestArtifact:
    """The artifact of a :class:`~synthesis.pipeline.SynthesizedTest` and its summary, with
    ``extras`` (e.g. provenance) added to its own."""
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
        extras={"history_descriptions": [spec.describe(h) for h in range(spec.dba.n_states)], **(extras or {})},
        source=problem_source_hash(p),
    )
