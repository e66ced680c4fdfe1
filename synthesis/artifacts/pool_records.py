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
(:func:`synthesis.test_agent.realize_agent_strategy`), and the table must have the size the
record states. Everything is deterministic: one record gives one artifact on every
machine. A record that fails raises :class:`ProblemError` naming the check.

A record carries the digest of its whole content (``digest``, :func:`record_digest`,
written by :func:`record_of`); :func:`rebuild_artifact` refuses a record whose digest is
missing or wrong (after the checks, so that a broken answer is named as such), so an edited record (one more cut, a summary
rewritten by hand) is never served, even where it would still pass the checks.

A record is trusted for which attempt it names (a rebuilt test is a checked test of that
attempt's problem; whether earlier attempts had none is what its builder found).
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..checks.verify import check_test
from ..model.errors import CheckFailed, InconsistentProblem, ProblemError
from ..pipeline import SynthesizedTest
from ..problems.problem import build_graphs
from ..problems.random_worlds import world_problem
from ..routing.restrictions import strategy_from_routing
from ..routing.result import RoutingResult
from ..test_agent.loop import AgentSynthesis, realize_agent_strategy
from .artifact import TestArtifact, artifact_of
from .summary import DERIVED_KEYS, DERIVED_STATS, derived_summary, without_timings

__all__ = ["RECORD_KEYS", "rebuild_artifact", "record_digest", "record_of"]

RECORD_KEYS: tuple[str, ...] = ("seed", "attempt", "cuts", "static", "summary", "digest")
"""The fields of a record, in the order they are written."""


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


def _indices(values: Any, bound: int, what: str) -> np.ndarray:
    """Distinct sorted integer indices below ``bound``."""
    if not isinstance(values, list) or not all(isinstance(v, int) and not isinstance(v, bool) for v in values):
        raise ProblemError(f"field {what} must be a list of integers")
    arr = np.asarray(values, dtype=np.int64)
    if arr.size and (int(arr.min()) < 0 or int(arr.max()) >= bound or bool(np.any(np.diff(arr) <= 0))):
        raise ProblemError(f"field {what} must hold distinct increasing indices below {bound}")
    return arr


def rebuild_artifact(
    record: dict[str, Any], size: int, family: str, n: int, world: str, kind: str, extras: Mapping[str, Any] | None = None
) -> TestArtifact:
    """The checked test of a record (see the module docstring), with ``extras`` added to the
    artifact's own.

    Raises
    ------
    ProblemError
        If the record is malformed or its test fails a check.
    """
    try:
        return _rebuild(record, size, family, n, world, kind, extras)
    except (CheckFailed, InconsistentProblem) as exc:
        raise ProblemError(f"pool record of seed {record.get('seed')!r} fails its check: {exc}") from None
    except EditedRecord as exc:
        raise ProblemError(f"pool record of seed {record.get('seed')!r}: {exc}") from None
    except (KeyError, TypeError, ValueError, AttributeError, IndexError, OverflowError) as exc:
        raise ProblemError(f"pool record of seed {record.get('seed')!r} is malformed ({type(exc).__name__}: {exc})") from None


def _rebuild(
    record: dict[str, Any], size: int, family: str, n: int, world: str, kind: str, extras: Mapping[str, Any] | None
) -> TestArtifact:
    if not isinstance(record, dict) or sorted(record) != sorted(RECORD_KEYS):
        raise ProblemError(f"a pool record has the fields {', '.join(RECORD_KEYS)}")
    seed, attempt, rest = record["seed"], record["attempt"], record["summary"]
    if not all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in (seed, attempt)):
        raise ProblemError("fields seed and attempt must be non-negative integers")
    if not isinstance(rest, dict) or not isinstance(rest.get("stats"), dict):
        raise ProblemError("field summary must be an object with stats")
    problem = world_problem(size, family, n, seed, attempt, world, kind)
    spec, products = build_graphs(problem)
    cuts = _indices(record["cuts"], products.virtual.n_edges, "cuts")
    static = np.zeros(products.ts.n_moves, dtype=bool)
    static[_indices(record["static"], products.ts.n_moves, "static")] = True
    flow = rest["flow"]
    if isinstance(flow, bool) or not isinstance(flow, int) or flow < 1:
        raise ProblemError("field summary.flow must be a positive integer")
    routing = RoutingResult(
        status=str(rest["status"]), flow=flow, cut_edges=cuts, cut_group_keys=[], static_moves_cut=static,
        blocked_places=np.zeros(0, dtype=np.int64), mip_gap=float(rest["stats"]["mip_gap"]), stats={},
    )
    strategy = strategy_from_routing(products, routing, problem.extras.get("setting", "instantaneous"))
    if not np.array_equal(strategy.static_obstacles, static):
        raise ProblemError("field static disagrees with the cuts")
    checks = check_test(products, strategy, flow)  # bypass flow 0, the flow, feasibility
    agent = None
    if problem.agent is not None:
        game, controller, report = realize_agent_strategy(products, strategy, problem.agent)
        stated = rest["agent_strategy"]
        got = {"game": game.size(), "table_entries": controller.n_entries, "closed_loop_positions": report.positions}
        if any(stated[k] != v for k, v in got.items()):
            raise CheckFailed(f"the rebuilt agent strategy ({got}) is not the one recorded")
        agent = AgentSynthesis(
            agent=problem.agent, controller=controller, system=products.ts, counterexamples=int(rest["counterexamples"]),
            iterations=[], game_size=game.size(), closed_loop=report, timings={},
        )
    derived = derived_summary(problem, spec, products, cuts, strategy, checks.bypass_flow)
    summary = {**derived, **{k: v for k, v in rest.items() if k != "stats"}, "stats": {**derived["stats"], **rest["stats"]}}
    # last, so that a record whose answer fails a check is told so: one that passes them all
    # but is not the record FlowTest wrote (one more cut, a summary edited) is refused here
    if record["digest"] != {"sha256": record_digest(record)}:
        raise EditedRecord("the record was changed after FlowTest wrote it (its digest is not that of its content)")
    # graph_seconds: not measured here; a rebuilt test's summary holds no timings
    test = SynthesizedTest(problem, spec, products, routing, strategy, checks, graph_seconds=0.0, agent=agent)
    return artifact_of(test, summary, extras)
