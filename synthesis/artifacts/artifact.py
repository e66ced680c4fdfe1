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
the flow of its summary, feasibility) and, for a test agent, its controller passes the
closed-loop check of :mod:`synthesis.test_agent.closed_loop` (its moves legal, the restrictions
realized exactly, the system never trapped). Any failure is a :class:`ProblemError` that
names what is wrong.

Before any of that, what can be checked on the plain data is (:func:`check_plain_data`):
every integer fits in 53 bits, every name is printable (no control characters), and the
sizes the file declares (histories times moves and states, the test agent's table, the
layout against the states) stay below :data:`MAX_TABLE_CELLS` and :data:`MAX_LAYOUT_CELLS`,
so a small file can never make FlowTest build huge tables.

**Identity.** Every artifact FlowTest writes carries a digest of its whole content
(:data:`DIGEST_KEY`, :func:`content_digest`). A file whose digest is missing or wrong was
not written as it is by FlowTest: where FlowTest made the file itself (a cache entry, a
shipped artifact) it is refused (``require_digest=True``); a user's own file is checked in
full and reported as edited (:class:`EditedArtifactWarning`, :attr:`TestArtifact.edited`).
"""

from __future__ import annotations

import hashlib
import json
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..checks.verify import check_test
from ..graphs.automata import DBA, specification_product
from ..graphs.products import build_products
from ..model.agent_system import Park, TestAgent, places_of_cells
from ..model.errors import CheckFailed, ProblemError, ProblemTooLarge
from ..model.specs import parse_objective
from ..model.strategy import TestStrategy
from ..model.systems import TransitionSystem
from ..problems.files import MAX_FILE_BYTES, read_limited
from ..problems.limits import check_file_size
from ..problems.problem import Problem
from ..synthesized_test import SynthesizedTest
from ..test_agent.closed_loop import verify_closed_loop
from ..test_agent.controller import AgentController
from .schema import validate_artifact

FORMAT = "flowtest-test"
VERSION = 1

DIGEST_KEY = "digest"
"""The top-level field holding :func:`content_digest` of the rest of the document, as
``{"sha256": "<64 lowercase hex digits>"}``."""

MAX_TABLE_CELLS = 2_000_000
"""Largest look-up table an artifact may declare (histories x moves, histories x states x
action slots, the test agent's memory x rows x states, the closed loop's configurations):
four times the product-graph edges synthesis allows by default
(:data:`synthesis.problems.limits.MAX_GRAPH_EDGES`, itself about 6 GB while solving), so
loading and checking any artifact FlowTest can make takes a few hundred MB at most."""

MAX_LAYOUT_CELLS = 1_000_000
"""Largest grid layout (rows x cols) an artifact may declare."""

MAX_EXPLORED_STATES = 100_000
"""At most this many automaton states are explored to derive an artifact's automata again
(seconds of work): a file cannot buy a longer search by declaring many histories."""

MAX_INT = 2**53
"""Integers in an artifact are below this in magnitude (what every JSON reader holds exactly)."""


class EditedArtifactWarning(UserWarning):
    """A user's artifact file was changed after FlowTest wrote it (its digest is missing or
    wrong); it was checked in full and is used as it is."""


def content_digest(doc: Mapping[str, Any]) -> str:
    """SHA-256 (hex) of an artifact document without its :data:`DIGEST_KEY` field, as
    canonical JSON (sorted keys, no spaces, ASCII).

    >>> content_digest({"name": "x"}) == content_digest({"name": "x", "digest": {"sha256": "0" * 64}})
    True
    """
    body = {k: v for k, v in doc.items() if k != DIGEST_KEY}
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    return hashlib.sha256(text.encode("ascii")).hexdigest()


def with_digest(doc: dict[str, Any]) -> dict[str, Any]:
    """``doc`` with its :data:`DIGEST_KEY` field (re)computed, last."""
    body = {k: v for k, v in doc.items() if k != DIGEST_KEY}
    return {**body, DIGEST_KEY: {"sha256": content_digest(body)}}


def digest_matches(doc: Mapping[str, Any]) -> bool:
    """Whether ``doc`` carries the digest of its own content (False if it has none)."""
    stated = doc.get(DIGEST_KEY)
    if not isinstance(stated, dict) or set(stated) != {"sha256"} or not isinstance(stated["sha256"], str):
        return False
    try:
        return bool(stated["sha256"] == content_digest(doc))
    except (TypeError, ValueError):
        return False


def _walk_plain(x: Any, path: str, source: str, names: bool = True) -> None:
    """Refuse integers beyond :data:`MAX_INT` and (``names``) strings with non-printable characters."""
    stack: list[tuple[Any, str]] = [(x, path)]
    while stack:
        v, at = stack.pop()
        if isinstance(v, str):
            if names and not v.isprintable():
                raise ProblemError(f"artifact {source}: field {at}: {v!r} holds a control or other non-printable character")
        elif isinstance(v, bool) or v is None:
            continue
        elif isinstance(v, int):
            if not -MAX_INT < v < MAX_INT:
                raise ProblemError(
                    f"artifact {source}: field {at}: an integer of about {int(v.bit_length() * 0.30103) + 1} digits is out of "
                    f"range (at most {MAX_INT} in magnitude)"
                )
        elif isinstance(v, float):
            continue
        elif isinstance(v, dict):
            for k, item in v.items():
                if names and not str(k).isprintable():
                    raise ProblemError(f"artifact {source}: field {at}: key {k!r} holds a non-printable character")
                stack.append((item, f"{at}.{k}" if at else str(k)))
        elif isinstance(v, list):
            stack.extend((item, f"{at}[{i}]") for i, item in enumerate(v))


def check_plain_data(d: Any, source: str) -> None:
    """What the plain data of an artifact must satisfy before any object is built from it
    (after the schema): integers within :data:`MAX_INT`, printable names (every string
    outside ``summary``), declared sizes within :data:`MAX_TABLE_CELLS` and
    :data:`MAX_LAYOUT_CELLS`, a grid layout that is its places and blocked cells.

    Raises
    ------
    ProblemError
        Naming the field; :class:`~synthesis.model.errors.ProblemTooLarge` for sizes.
    """
    if not isinstance(d, dict):
        return
    for key, value in d.items():
        _walk_plain(value, key, source, names=key != "summary")  # the summary's texts are not names
    _check_declared_sizes(d, source)


def _check_declared_sizes(d: dict[str, Any], source: str) -> None:
    where = f"artifact {source}"
    s = d["system"]
    n, m, n_places = len(s["states"]), len(s["moves"]), len(s["places"])
    nh = len(d["automata"]["histories"]["delta"])
    if s["kind"] == "graph":
        out = np.bincount(np.asarray([mv[0] for mv in s["moves"]], dtype=np.int64), minlength=n) if m else np.zeros(1)
        slots = max(1, int(out.max()))
    else:
        slots = 4
    big = MAX_TABLE_CELLS

    def refuse(what: str, value: int) -> None:
        raise ProblemTooLarge(f"{where} declares {what} = {value} table cells, above the limit of {big}; FlowTest builds no tables this large")

    if nh * m > big:
        refuse(f"{nh} histories x {m} moves", nh * m)
    if nh * n * (slots + 1) > big:
        refuse(f"{nh} histories x {n} states x {slots + 1} actions", nh * n * (slots + 1))
    lay = s.get("layout")
    if lay is not None:
        rows, cols = lay["rows"], lay["cols"]
        if rows * cols > MAX_LAYOUT_CELLS:
            raise ProblemTooLarge(f"{where}: field system.layout: {rows}x{cols} cells, above the limit of {MAX_LAYOUT_CELLS}")
        cells = [tuple(p) for p in s["places"] if isinstance(p, list)]
        if len(cells) != n_places:
            raise ProblemError(f"{where}: field system.places: a grid's places are cells [row, col]")
        outside = [list(c) for c in cells if not (c[0] < rows and c[1] < cols)]
        if outside:
            raise ProblemError(f"{where}: field system.places: {outside[0]} is outside the {rows}x{cols} layout")
        blocked = {tuple(c) for c in lay["blocked"]}
        if s["kind"] == "grid" and (len(set(cells)) + len(blocked - set(cells)) != rows * cols or blocked & set(cells)):
            raise ProblemError(
                f"{where}: field system.layout: a {rows}x{cols} layout for a system of {n_places} places and "
                f"{len(blocked)} blocked cells (a grid's layout is exactly its places and blocked cells)"
            )
    agent = d.get("agent")
    if isinstance(agent, dict) and isinstance(agent.get("controller"), dict):
        c = agent["controller"]
        na, n_mem, n_rows = len(c["agent_names"]), c["n_memory"], len(c["rows"])
        if n_mem * n_rows * na > big:
            refuse(f"the test agent's {n_mem} memories x {n_rows} rows x {na} states", n_mem * n_rows * na)
        if na * na > big:
            refuse(f"the test agent's {na} x {na} moves", na * na)
        if nh * n * na * n_mem > 4 * big:
            refuse(f"{nh} histories x {n} states x {na} agent states x {n_mem} memories", nh * n * na * n_mem)


def source_hash(system: dict[str, Any], objectives: dict[str, Any], kind: str) -> str:
    """SHA-256 of what a test is synthesized from: the transition system (as the artifact
    writes it), the two objective texts and the environment kind, as canonical JSON."""
    doc = {"format": FORMAT, "system": system, "objectives": {"system": objectives["system"], "test": objectives["test"]}, "kind": kind}
    text = json.dumps(doc, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    return hashlib.sha256(text.encode("ascii")).hexdigest()


def problem_source_hash(problem: Problem) -> str:
    """:func:`source_hash` of a :class:`~synthesis.problems.problem.Problem` (before synthesis)."""
    return source_hash(problem.system.to_dict(), {"system": problem.system_objective.text, "test": problem.test_objective.text}, problem.kind)


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

    Examples
    --------
    >>> import pathlib, tempfile
    >>> from synthesis import TestArtifact, artifact_of, load_problem, summary_of, synthesize
    >>> test = synthesize(load_problem("small-reactive"))
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = pathlib.Path(folder, "small-reactive.json")
    ...     artifact_of(test, summary_of(test)).save(path)
    ...     loaded = TestArtifact.load(path)    # checked against what it claims
    >>> loaded.name, loaded.kind, loaded.summary["n_cuts"], loaded.edited
    ('small-reactive', 'reactive', 4, False)
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
    edited: bool = field(default=False, compare=False)
    """Loaded from a file whose digest was missing or wrong (checked in full, see the module docstring)."""
    _letter: np.ndarray = field(init=False, repr=False, compare=False)  # letter index of each state

    @property
    def static_area(self) -> np.ndarray | None:
        """A mixed test's static area as the problem typed it in (``bool`` per move: the moves
        where a wall may stand, whether or not one does), from ``extras["static_moves"]``;
        ``None`` for other kinds and for files written before FlowTest carried it. Running
        the test needs none of it: the pictures draw it."""
        area = self.extras.get("static_moves")
        if area is None:
            return None
        mask = np.zeros(self.system.n_moves, dtype=bool)
        mask[np.asarray(area, dtype=np.int64)] = True
        return mask

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
        """The artifact's plain data, with its :data:`DIGEST_KEY` last."""
        return with_digest(
            {
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
        )

    @classmethod
    def from_dict(cls, d: dict[str, Any], source: str = "<artifact>", verify: bool = True, require_digest: bool = False) -> TestArtifact:
        """Build an artifact from its plain data, checked first (see the module docstring).

        A document whose digest is missing or wrong is checked in full whatever ``verify``
        says (a failed check is what the error names); then ``require_digest=True`` (files
        FlowTest wrote itself) refuses it all the same, otherwise an
        :class:`EditedArtifactWarning` is issued and the artifact's :attr:`edited` is set.

        Raises
        ------
        ProblemError
            Naming the field or the check that fails. ``verify=False`` skips the
            checks of meaning (:func:`verify_artifact`) of a document whose digest
            matches, never the schema, the plain-data checks or the digest.
        """
        validate_artifact(d, source, FORMAT, VERSION)
        check_plain_data(d, source)
        edited = not digest_matches(d)
        how = "missing" if DIGEST_KEY not in d else "not that of its content"
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
                edited=edited,
            )
        except (KeyError, IndexError, TypeError, ValueError, AttributeError, OverflowError) as exc:
            # the schema should have said it; never let a raw error reach a user
            raise ProblemError(f"artifact {source} is malformed ({type(exc).__name__}: {exc})") from None
        if verify or edited:
            verify_artifact(art, source)  # an edited file is checked in full, whatever ``verify`` says
        if edited and require_digest:  # it passes every check, but it is not the file FlowTest wrote
            raise ProblemError(f"artifact {source} was changed after FlowTest wrote it (its digest is {how})")
        if edited:
            warnings.warn(
                EditedArtifactWarning(
                    f"artifact {source} was changed after FlowTest wrote it (its digest is {how}): it passed every check again and is used as edited"
                ),
                stacklevel=2,
            )
        return art

    def save(self, path: str | Path) -> None:
        """Write the artifact as compact JSON (with its digest)."""
        Path(path).write_text(json.dumps(self.to_dict(), separators=(",", ":")))

    @classmethod
    def load(cls, path: str | Path, verify: bool = True, require_digest: bool = False) -> TestArtifact:
        """Read and check an artifact file of at most 16 MiB, its size checked before it is
        read (see :meth:`from_dict`)."""
        p = Path(path)
        check_file_size(p, "artifact", MAX_FILE_BYTES)
        raw = read_limited(p, "artifact")
        return cls.from_dict(parse_artifact_json(raw, str(p)), str(p), verify, require_digest)


def parse_artifact_json(raw: bytes, source: str) -> Any:
    """The parsed JSON of an artifact file's bytes (raises ProblemError, never a raw error:
    not UTF-8, invalid JSON, nested too deeply, an integer too long to convert)."""
    try:
        return json.loads(raw.decode("utf-8"))
    except UnicodeDecodeError:
        raise ProblemError(f"artifact {source!r} is not UTF-8 text") from None
    except json.JSONDecodeError as exc:
        raise ProblemError(f"{source}: invalid JSON: {exc}") from None
    except RecursionError:
        raise ProblemError(f"{source}: invalid JSON: nested too deeply") from None
    except ValueError as exc:  # e.g. an integer of more than 4300 digits
        raise ProblemError(f"{source}: invalid JSON: {exc}") from None


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


def verify_artifact(art: TestArtifact, source: str = "<artifact>", expected_source: str | None = None, restrictions: bool = True) -> None:
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

    Examples
    --------
    >>> from dataclasses import replace
    >>> from synthesis import artifact_of, load_problem, summary_of, synthesize, verify_artifact
    >>> test = synthesize(load_problem("small-reactive"))
    >>> artifact = artifact_of(test, summary_of(test))
    >>> verify_artifact(artifact)        # passes: returns None
    >>> edited = replace(artifact, objectives={"system": "F goal", "test": "F I1"})
    >>> verify_artifact(edited, source="edited.json")
    Traceback (most recent call last):
    ...
    synthesis.model.errors.ProblemError: artifact edited.json: its system, objectives or kind do not match its source hash (the file was edited)
    """
    where = f"artifact {source}"
    own = source_hash(art.system.to_dict(), art.objectives, art.kind)
    if art.source != own:
        raise ProblemError(f"{where}: its system, objectives or kind do not match its source hash (the file was edited)")
    if expected_source is not None and art.source != expected_source:
        raise ProblemError(f"{where} was synthesized from another problem than the one asked for (source hash mismatch)")
    area = art.static_area
    if area is not None and bool((art.strategy.static_obstacles & ~area).any()):
        m = int(np.flatnonzero(art.strategy.static_obstacles & ~area)[0])
        raise ProblemError(f"{where}: field strategy.static_obstacles: move {m} is a wall outside the static area of extras.static_moves (the file was edited)")
    if art.letters != art.system.letters():
        raise ProblemError(f"{where}: field letters is not the alphabet of its system's labels")
    # the automata derived again are compared with those the file declares: no larger product is explored
    bound = min(64 * max(art.histories.n_states, art.system_automaton.n_states, art.test_automaton.n_states), MAX_EXPLORED_STATES)
    try:
        spec = specification_product(
            parse_objective(art.objectives["system"], "system"),
            parse_objective(art.objectives["test"], "test"),
            art.letters,
            max_states=bound,
        )
    except ProblemTooLarge:
        raise ProblemError(f"{where}: field automata is not the automaton of its objectives (these need more than {bound} states)") from None
    except ProblemError as exc:
        raise ProblemError(f"{where}: field objectives: {exc}") from None
    for field_name, mine, derived in (
        ("system", art.system_automaton, spec.sys),
        ("test", art.test_automaton, spec.test),
        ("histories", art.histories, spec.dba),
    ):
        if not _same_dba(mine, derived):
            raise ProblemError(f"{where}: field automata.{field_name} is not the automaton of its objectives (edited, or another problem's automata)")
    if not restrictions:
        return
    products = build_products(art.system, spec)
    report = check_test(products, art.strategy, int(art.summary["flow"]), raise_on_failure=False)
    if not report.ok:
        raise ProblemError(f"{where}: its restrictions fail the independent check: " + "; ".join(report.problems()))
    if art.kind == "agent":
        agent, controller = artifact_agent(art, where)
        try:
            verify_closed_loop(products, art.strategy, agent, controller)
        except CheckFailed as exc:
            raise ProblemError(f"{where}: its test agent does not realize its restrictions: {exc}") from None


def artifact_agent(art: TestArtifact, where: str | None = None) -> tuple[TestAgent, AgentController]:
    """The test agent ``T_TA`` and its controller stored in an agent artifact, checked to
    agree with each other (names, places, start, who moves first).

    Raises
    ------
    ProblemError
        If the artifact has no test agent or its two descriptions disagree.
    """
    where = where or f"artifact {art.name!r}"
    d = art.agent
    if not isinstance(d, dict) or not isinstance(d.get("controller"), dict):
        raise ProblemError(f"{where}: field agent: an agent test needs its test agent and controller")
    ts = art.system
    try:
        controller = AgentController.from_dict(d["controller"])
        cells = places_of_cells(ts, d["cells"], f"{where}: field agent.cells")
        names = [str(x) for x in d["names"]]
        state_of = {p: i for i, p in enumerate(cells)}
        parks = [Park(str(p["name"]), tuple(state_of[q] for q in places_of_cells(ts, p["from"], f"{where}: field agent.parks"))) for p in d["parks"]]
        moves = np.asarray(d["moves"], dtype=np.int64).reshape(-1, 2)
        agent = TestAgent(cells=np.asarray(cells, dtype=np.int32), parks=parks, start=names.index(d["start"]), moves=moves, first=str(d["first"]), names=names)
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise ProblemError(f"{where}: field agent is malformed ({type(exc).__name__}: {exc})") from None
    n_states = agent.n_states
    if len(names) != n_states or len(cells) != len(d["cells"]):
        raise ProblemError(f"{where}: field agent.names: {len(names)} names for {n_states} agent states")
    if moves.size and (int(moves.min()) < 0 or int(moves.max()) >= n_states):
        raise ProblemError(f"{where}: field agent.moves: a move between agent states outside 0..{n_states - 1}")
    places = [None if p < 0 else int(p) for p in agent.place_of_state]
    if controller.agent_names != names or controller.agent_places != places or controller.first != agent.first or controller.initial_agent != agent.start:
        raise ProblemError(
            f"{where}: field agent.controller does not belong to the test agent described beside it (names, places, start or first mover differ)"
        )
    return agent, controller


def artifact_of(test: SynthesizedTest, summary: dict[str, Any], extras: Mapping[str, Any] | None = None) -> TestArtifact:
    """The artifact of a :class:`~synthesis.synthesized_test.SynthesizedTest` and its summary, with
    ``extras`` (e.g. provenance) added to its own.

    Examples
    --------
    >>> from synthesis import artifact_of, load_problem, summary_of, synthesize
    >>> test = synthesize(load_problem("small-reactive"))
    >>> artifact = artifact_of(test, summary_of(test), extras={"built_by": "example"})
    >>> artifact.name, artifact.kind, artifact.summary["flow"], artifact.extras["built_by"]
    ('small-reactive', 'reactive', 2, 'example')
    """
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
        extras={**_own_extras(test), **(extras or {})},
        source=problem_source_hash(p),
    )


def _own_extras(test: SynthesizedTest) -> dict[str, Any]:
    """What an artifact carries about its test beyond running it: each history's meaning and,
    for a mixed test, the static area typed in (``static_moves``: move indices), so a picture
    of the artifact draws the area as ``flowtest synthesize --plot`` does."""
    p, spec = test.problem, test.spec
    out: dict[str, Any] = {"history_descriptions": [spec.describe(h) for h in range(spec.dba.n_states)]}
    if p.kind == "mixed" and p.static_moves is not None:
        out["static_moves"] = np.flatnonzero(np.asarray(p.static_moves, dtype=bool)).tolist()
    return out
