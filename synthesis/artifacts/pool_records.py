"""Compact pool records: what a pool test stores besides its seed, and the test rebuilt from it.

A pool test's problem comes back from its seed (:mod:`synthesis.problems.random_worlds`); its
automata, product graphs and most of its summary come back from the problem. What does
not is the solver's answer: which attempt of the seed was the first with a test, the cut
edges of G (indices), the static obstacles (move indices of T), and the summary fields
that say how the solver got there (status, flow, model sizes, the test agent's
counterexamples...), without timings. That is a :func:`record_of` record, a few hundred
bytes where the full artifact JSON takes kilobytes.

:func:`rebuild_artifact` turns a record back into a :class:`~synthesis.artifacts.artifact.TestArtifact`
and checks it as a fresh synthesis is checked: the restrictions pass
:func:`synthesis.checks.verify.check_test` (bypass flow 0, the stated flow, a way to the goal
from every history's entry nodes); for a test agent, the GR(1) game of the restrictions
is solved again and its strategy checked and tabulated
(:func:`synthesis.test_agent.realize.realize_agent_strategy`), and the table must have the size the
record states. Everything is deterministic: one record gives one artifact on every
machine. A record that fails raises :class:`ProblemError` naming the check.

A record carries the digest of its whole content (``digest``, :func:`record_digest`,
written by :func:`record_of`); :func:`rebuild_artifact` refuses a record whose digest is
missing or wrong (after the checks, so that a broken answer is named as such), so an edited record (one more cut, a summary
rewritten by hand) is never served, even where it would still pass the checks.

A record is trusted for which attempt it names (a rebuilt test is a checked test of that
attempt's problem; whether earlier attempts had none is what its builder found).

**Certified records** (the standard pools shipped with FlowTest) also carry a
``certificate`` (:func:`certify`, covered by the digest): a SHA-256 of the restrictions the
full check passed (the product sizes, the history-by-move table of restricted moves, the
static walls) and the flow it measured. ``rebuild_artifact(..., check="certificate")``
checks the digest first, rebuilds the problem, products and restrictions from the seed
and cuts (what an environment needs anyway), and instead of the full check compares the
restrictions with the certified ones and searches once that no path avoids the test
objective (bypass flow 0, one graph search). It skips the max-flow and the
per-history trap searches, which dominate a full check: the certificate says those passed
on exactly these restrictions, and any change to the restrictions, the products built from
the seed or the record shows as a mismatch. ``check="full"`` (the default) runs every
check whatever the record carries.

**Content keys** (the ``-v2`` standard pools, drawn disjoint by content): a record may also
carry ``content``, the content key of its test (:func:`synthesis.artifacts.content.content_key`:
which game a policy plays, not its name, seed or statistics), written by
``certify(..., content=True)`` and covered by the digest. Either check recomputes it from
the rebuilt test and refuses a record whose test is not the one its key names, so the key
a pool's disjointness is checked with is the key of the test it serves.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..checks.verify import CheckReport, check_test, restricted_edges
from ..graphs.automata import SpecificationProduct, specification_product
from ..graphs.products import Products, build_products, reachable
from ..model.errors import CheckFailed, InconsistentProblem, ProblemError
from ..model.strategy import TestStrategy
from ..problems.problem import Problem, build_graphs
from ..problems.random_worlds import world_problem
from ..routing.restrictions import strategy_from_routing
from ..routing.result import RoutingResult
from ..synthesized_test import SynthesizedTest
from ..test_agent.realize import AgentSynthesis, realize_agent_strategy
from .artifact import TestArtifact, artifact_of
from .content import content_key
from .summary import DERIVED_KEYS, DERIVED_STATS, derived_summary, without_timings

__all__ = ["CHECKS", "OPTIONAL_KEYS", "RECORD_KEYS", "certificate_of", "certify", "rebuild_artifact", "record_content_key", "record_digest", "record_of"]

RECORD_KEYS: tuple[str, ...] = ("seed", "attempt", "cuts", "static", "summary", "digest")
"""The fields of a record, in the order they are written (a certified record has
``certificate`` too, and may have ``content``: :data:`OPTIONAL_KEYS`)."""

OPTIONAL_KEYS: tuple[str, ...] = ("certificate", "content")
"""Fields a record may carry besides :data:`RECORD_KEYS`: the certificate of its checked
restrictions (:func:`certify`) and its test's content key (``certify(..., content=True)``)."""

CHECKS: tuple[str, ...] = ("full", "certificate")
"""How :func:`rebuild_artifact` checks a record: every check, or the certificate."""


class EditedRecord(ProblemError):
    """A record that is not the one FlowTest wrote (its digest is missing or wrong)."""


def record_digest(record: Mapping[str, Any]) -> str:
    """SHA-256 (hex) of a record without its ``digest`` field, as canonical JSON (sorted
    keys, no spaces, ASCII): the same definition as an artifact's
    (:func:`synthesis.artifacts.artifact.content_digest`)."""
    body = {k: v for k, v in record.items() if k != "digest"}
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    return hashlib.sha256(text.encode("ascii")).hexdigest()


def record_of(seed: int, attempt: int, test: SynthesizedTest, summary: dict[str, Any]) -> dict[str, Any]:
    """The compact record of a synthesized pool test (its summary without what comes back
    from the problem and without timings)."""
    rest = without_timings({k: v for k, v in summary.items() if k not in DERIVED_KEYS})
    rest["stats"] = {k: v for k, v in rest["stats"].items() if k not in DERIVED_STATS}
    record: dict[str, Any] = {
        "seed": int(seed),
        "attempt": int(attempt),
        "cuts": [int(e) for e in test.routing.cut_edges],
        "static": [int(m) for m in np.flatnonzero(test.strategy.static_obstacles)],
        "summary": rest,
    }
    record["digest"] = {"sha256": record_digest(record)}
    return record


def certificate_of(products: Products, strategy: TestStrategy, flow: int) -> dict[str, Any]:
    """The certificate of a checked test: SHA-256 of its product sizes, flow, static walls
    and history-by-move restricted table (packed bits), as ``{"sha256": hex}``."""
    g, gs = products.virtual, products.system
    head = json.dumps([g.n_nodes, g.n_edges, gs.n_nodes, gs.n_edges, list(strategy.blocked.shape), int(flow)])
    h = hashlib.sha256(head.encode("ascii"))
    h.update(np.packbits(np.asarray(strategy.blocked, dtype=bool)).tobytes())
    h.update(np.packbits(np.asarray(strategy.static_obstacles, dtype=bool)).tobytes())
    return {"sha256": h.hexdigest()}


def certify(record: dict[str, Any], size: int, family: str, n: int, world: str, kind: str, content: bool = False) -> dict[str, Any]:
    """A record with its certificate: the test rebuilt and fully checked
    (:func:`rebuild_artifact`), then the certificate of what passed (and, with ``content``,
    the content key of the test, :func:`synthesis.artifacts.content.content_key`), and the
    digest written again over the whole.

    Raises
    ------
    ProblemError
        If the record fails a check (an uncertifiable record is never certified).
    """
    plain = {k: v for k, v in record.items() if k not in OPTIONAL_KEYS}
    if any(k in record for k in OPTIONAL_KEYS):  # certified before: its digest must hold, then it is written anew
        try:
            _check_digest(record)
        except (EditedRecord, KeyError) as exc:
            raise ProblemError(f"pool record of seed {record.get('seed')!r}: {exc}") from None
        plain["digest"] = {"sha256": record_digest(plain)}
    art, products, strategy = _rebuilt(plain, size, family, n, world, kind, None, "full")
    out = {**plain, "certificate": certificate_of(products, strategy, int(plain["summary"]["flow"]))}
    if content:
        out["content"] = {"sha256": content_key(art)}
    out["digest"] = {"sha256": record_digest(out)}
    return out


def record_content_key(record: Mapping[str, Any]) -> str | None:
    """The content key a record states (``None`` if it carries none), unchecked: loading the
    record (:func:`rebuild_artifact`) checks it against its test."""
    content = record.get("content")
    key = content.get("sha256") if isinstance(content, Mapping) else None
    return key if isinstance(key, str) else None


def _indices(values: Any, bound: int, what: str) -> np.ndarray:
    """Distinct sorted integer indices below ``bound``."""
    if not isinstance(values, list) or not all(isinstance(v, int) and not isinstance(v, bool) for v in values):
        raise ProblemError(f"field {what} must be a list of integers")
    arr = np.asarray(values, dtype=np.int64)
    if arr.size and (int(arr.min()) < 0 or int(arr.max()) >= bound or bool(np.any(np.diff(arr) <= 0))):
        raise ProblemError(f"field {what} must hold distinct increasing indices below {bound}")
    return arr


def rebuild_artifact(
    record: dict[str, Any],
    size: int,
    family: str,
    n: int,
    world: str,
    kind: str,
    extras: Mapping[str, Any] | None = None,
    check: str = "full",
) -> TestArtifact:
    """The checked test of a record (see the module docstring), with ``extras`` added to the
    artifact's own.

    ``check="full"`` runs every check of a fresh synthesis; ``check="certificate"`` checks
    the digest first, then the record's certificate (a record without one is refused).

    Example::

        art = rebuild_artifact(record, 5, "reachability", 1, "empty", "reactive")

    Raises
    ------
    ProblemError
        If the record is malformed, edited, or its test fails a check.
    """
    return _rebuilt(record, size, family, n, world, kind, extras, check)[0]


def _rebuilt(
    record: dict[str, Any], size: int, family: str, n: int, world: str, kind: str, extras: Mapping[str, Any] | None, check: str
) -> tuple[TestArtifact, Products, TestStrategy]:
    """:func:`rebuild_artifact` with the products and strategy it rebuilt."""
    if check not in CHECKS:
        raise ValueError(f"unknown check {check!r}; expected one of {', '.join(CHECKS)}")
    seed = record.get("seed") if isinstance(record, dict) else None
    try:
        return _rebuild(record, size, family, n, world, kind, extras, check)
    except (CheckFailed, InconsistentProblem) as exc:
        raise ProblemError(f"pool record of seed {seed!r} fails its check: {exc}") from None
    except EditedRecord as exc:
        raise ProblemError(f"pool record of seed {seed!r}: {exc}") from None
    except (KeyError, TypeError, ValueError, AttributeError, IndexError, OverflowError) as exc:
        raise ProblemError(f"pool record of seed {seed!r} is malformed ({type(exc).__name__}: {exc})") from None


_SPECS: dict[Any, SpecificationProduct] = {}


def _graphs(problem: Problem) -> tuple[SpecificationProduct, Products]:
    """:func:`synthesis.problems.problem.build_graphs`, with the specification product
    shared between the problems of one pool that have the same objectives and letters
    (it depends on nothing else; most tests of a pool share a few)."""
    ts = problem.system
    key = (problem.system_objective, problem.test_objective, ts.letters())
    try:
        spec = _SPECS.get(key)
    except TypeError:  # an unhashable objective: build as usual
        return build_graphs(problem)
    if spec is None:
        if len(_SPECS) >= 256:
            _SPECS.clear()
        spec = _SPECS[key] = specification_product(problem.system_objective, problem.test_objective, ts.letters())
    return spec, build_products(ts, spec)


def _check_digest(record: dict[str, Any]) -> None:
    if record["digest"] != {"sha256": record_digest(record)}:
        raise EditedRecord("the record was changed after FlowTest wrote it (its digest is not that of its content)")


SMALL_GRAPH = 20_000
"""Edges up to which :func:`_bypass_free` searches in plain Python (a pool test's product
has a few hundred: faster than building a sparse matrix for the search)."""


def _bypass_free(products: Products, strategy: TestStrategy) -> bool:
    """Whether no path of G from ``Src`` to ``Tgt`` avoids ``E(I)`` under the restrictions
    (bypass flow 0, by one graph search instead of a maximum flow: depth first over
    adjacency lists on a small G, breadth first over a sparse matrix on a large one)."""
    g = products.virtual
    keep = ~products.touches_intermediate & ~restricted_edges(products, strategy)
    src, dst = g.src[keep], g.dst[keep]
    if src.size > SMALL_GRAPH:
        reach = reachable(g.n_nodes, src, dst, np.arange(g.n_nodes) == g.initial)
        return not bool(np.any(reach & products.target))
    order = np.argsort(src, kind="stable")
    start = np.searchsorted(src[order], np.arange(g.n_nodes + 1)).tolist()
    heads = dst[order].tolist()
    target = products.target.tolist()
    seen = [False] * g.n_nodes
    seen[g.initial] = True
    todo = [int(g.initial)]
    while todo:
        u = todo.pop()
        if target[u]:
            return False
        for v in heads[start[u] : start[u + 1]]:
            if not seen[v]:
                seen[v] = True
                todo.append(v)
    return True


def _rebuild(
    record: dict[str, Any], size: int, family: str, n: int, world: str, kind: str, extras: Mapping[str, Any] | None, check: str
) -> tuple[TestArtifact, Products, TestStrategy]:
    keys = sorted(RECORD_KEYS)
    if not isinstance(record, dict) or sorted(k for k in record if k not in OPTIONAL_KEYS) != keys:
        raise ProblemError(f"a pool record has the fields {', '.join(RECORD_KEYS)} (and certificate, if certified, and content, if keyed)")
    if "content" in record and record_content_key(record) is None:
        raise ProblemError('field content must be {"sha256": <hex>}')
    if check == "certificate":
        if not isinstance(record.get("certificate"), dict):
            raise ProblemError("the record has no certificate (load it with check='full')")
        _check_digest(record)  # first: an edited record costs nothing more
    seed, attempt, rest = record["seed"], record["attempt"], record["summary"]
    if not all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in (seed, attempt)):
        raise ProblemError("fields seed and attempt must be non-negative integers")
    if not isinstance(rest, dict) or not isinstance(rest.get("stats"), dict):
        raise ProblemError("field summary must be an object with stats")
    problem = world_problem(size, family, n, seed, attempt, world, kind)
    spec, products = _graphs(problem)
    cuts = _indices(record["cuts"], products.virtual.n_edges, "cuts")
    static = np.zeros(products.ts.n_moves, dtype=bool)
    static[_indices(record["static"], products.ts.n_moves, "static")] = True
    flow = rest["flow"]
    if isinstance(flow, bool) or not isinstance(flow, int) or flow < 1:
        raise ProblemError("field summary.flow must be a positive integer")
    routing = RoutingResult(
        status=str(rest["status"]),
        flow=flow,
        cut_edges=cuts,
        cut_group_keys=[],
        static_moves_cut=static,
        blocked_places=np.zeros(0, dtype=np.int64),
        mip_gap=float(rest["stats"]["mip_gap"]),
        stats={},
    )
    strategy = strategy_from_routing(products, routing, problem.extras.get("setting", "instantaneous"))
    if not np.array_equal(strategy.static_obstacles, static):
        raise ProblemError("field static disagrees with the cuts")
    if check == "certificate":
        if record["certificate"] != certificate_of(products, strategy, flow):
            raise CheckFailed("the restrictions rebuilt from the record are not the ones its certificate says were checked")
        if not _bypass_free(products, strategy):
            raise CheckFailed("bypass flow is not 0: some execution avoids the test objective")
        checks = CheckReport(bypass_flow=0, flow=flow, expected_flow=flow)  # the rest: as certified
    else:
        checks = check_test(products, strategy, flow)  # bypass flow 0, the flow, feasibility
    agent = None
    if problem.agent is not None:
        game, controller, report = realize_agent_strategy(products, strategy, problem.agent)
        stated = rest["agent_strategy"]
        got = {"game": game.size(), "table_entries": controller.n_entries, "closed_loop_positions": report.positions}
        if any(stated[k] != v for k, v in got.items()):
            raise CheckFailed(f"the rebuilt agent strategy ({got}) is not the one recorded")
        agent = AgentSynthesis(
            agent=problem.agent,
            controller=controller,
            system=products.ts,
            counterexamples=int(rest["counterexamples"]),
            iterations=[],
            game_size=game.size(),
            closed_loop=report,
            timings={},
        )
    derived = derived_summary(problem, spec, products, cuts, strategy, checks.bypass_flow)
    summary = {**derived, **{k: v for k, v in rest.items() if k != "stats"}, "stats": {**derived["stats"], **rest["stats"]}}
    # graph_seconds: not measured here; a rebuilt test's summary holds no timings
    test = SynthesizedTest(problem, spec, products, routing, strategy, checks, graph_seconds=0.0, agent=agent)
    art = artifact_of(test, summary, extras)
    stated = record_content_key(record)
    if stated is not None and stated != content_key(art):
        raise CheckFailed("the test rebuilt from the record is not the one its content key names")
    if check == "full":
        # last, so that a record whose answer fails a check is told so: one that passes
        # them all but is not the record FlowTest wrote (one more cut, a summary edited)
        # is refused here (the certificate check did it first)
        _check_digest(record)
    return art, products, strategy
