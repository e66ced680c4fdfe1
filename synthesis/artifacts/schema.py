"""The schema of the synthesized-test artifact: every field, its type and its index range.

:func:`validate_artifact` checks the plain data of an artifact (parsed JSON) before any
object is built from it, so a damaged or edited file is refused with a message that
names the field (``automata.test.delta[3][1]: 9 is outside 0..4``), never with a raw
``KeyError``/``IndexError`` from deep inside the environment. It checks shape only;
:func:`synthesis.artifacts.artifact.verify_artifact` then checks meaning (the source hash, the
automata against the objectives, the restrictions against the product graphs).
"""

from __future__ import annotations

import json
import re
import sys
from typing import Any

from ..model.errors import ProblemError
from ..model.strategy import SETTINGS
from ..model.systems import MOVES
from ..problems.problem import KINDS

SYSTEM_KINDS = ("grid", "fuel", "graph")
GRID_MOVE_NAMES: tuple[str, ...] = tuple(MOVES)
"""The move names of a grid (``N``, ``S``, ``E``, ``W``: :data:`synthesis.model.systems.MOVES`), which a grid
with its map must use (its action slots 0-3, ``flowtest_env.game.GRID_ACTIONS``)."""
_HEX64 = re.compile(r"[0-9a-f]{64}")


class _Where:
    """Builds messages naming the artifact and the field."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, path: str, what: str) -> ProblemError:
        return ProblemError(f"artifact {self.source}: field {path}: {what}")


def _is_int(x: Any) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def _get(w: _Where, d: dict[str, Any], key: str, path: str) -> Any:
    if key not in d:
        raise w.fail(f"{path}.{key}" if path else key, "missing")
    return d[key]


def _dict(w: _Where, v: Any, path: str) -> dict[str, Any]:
    if not isinstance(v, dict):
        raise w.fail(path, f"must be an object, not {type(v).__name__}")
    return v


def _list(w: _Where, v: Any, path: str, length: int | None = None) -> list[Any]:
    if not isinstance(v, list):
        raise w.fail(path, f"must be a list, not {type(v).__name__}")
    if length is not None and len(v) != length:
        raise w.fail(path, f"has {len(v)} entries, expected {length}")
    return v


def _str(w: _Where, v: Any, path: str) -> str:
    if not isinstance(v, str):
        raise w.fail(path, f"must be a string, not {type(v).__name__}")
    return v


def _int(w: _Where, v: Any, path: str, lo: int = 0, hi: int | None = None) -> int:
    """An integer in ``lo..hi-1`` (booleans are not integers)."""
    if not _is_int(v):
        raise w.fail(path, f"{v!r} is not an integer")
    if v < lo or (hi is not None and v >= hi):
        span = f"{lo}..{hi - 1}" if hi is not None else f">= {lo}"
        raise w.fail(path, f"{v} is outside {span}")
    return int(v)


def _ints(w: _Where, v: Any, path: str, lo: int, hi: int | None, length: int | None = None) -> list[int]:
    items = _list(w, v, path, length)
    for i, x in enumerate(items):
        _int(w, x, f"{path}[{i}]", lo, hi)
    return items


def _bits(w: _Where, v: Any, path: str, length: int) -> list[int]:
    return _ints(w, v, path, 0, 2, length)


def _strs(w: _Where, v: Any, path: str, length: int | None = None) -> list[str]:
    items = _list(w, v, path, length)
    for i, x in enumerate(items):
        _str(w, x, f"{path}[{i}]")
    return items


def _cell(w: _Where, v: Any, path: str) -> None:
    _ints(w, v, path, 0, None, 2)


def _system(w: _Where, s: Any, path: str) -> tuple[int, int, int]:
    """Check the transition system; return ``(n_states, n_moves, n_places)``."""
    s = _dict(w, s, path)
    kind = _str(w, _get(w, s, "kind", path), f"{path}.kind")
    if kind not in SYSTEM_KINDS:
        raise w.fail(f"{path}.kind", f"{kind!r} is not one of {', '.join(SYSTEM_KINDS)}")
    states = _list(w, _get(w, s, "states", path), f"{path}.states")
    n = len(states)
    if n == 0:
        raise w.fail(f"{path}.states", "is empty")
    for i, st in enumerate(states):
        at = f"{path}.states[{i}]"
        if kind == "grid":
            _cell(w, st, at)
        elif kind == "fuel":
            pair = _list(w, st, at, 2)
            _cell(w, pair[0], f"{at}[0]")
            _int(w, pair[1], f"{at}[1]")
        else:
            _str(w, st, at)
    moves = _list(w, _get(w, s, "moves", path), f"{path}.moves")
    m = len(moves)
    for i, mv in enumerate(moves):
        _ints(w, mv, f"{path}.moves[{i}]", 0, n, 2)
    action = _list(w, _get(w, s, "action", path), f"{path}.action", m)
    for i, a in enumerate(action):
        if not isinstance(a, str) and not _is_int(a):
            raise w.fail(f"{path}.action[{i}]", f"{a!r} is neither a name nor an integer")
    _bits(w, _get(w, s, "stay", path), f"{path}.stay", n)
    _int(w, _get(w, s, "initial", path), f"{path}.initial", 0, n)
    labels = _list(w, _get(w, s, "labels", path), f"{path}.labels", n)
    for i, lab in enumerate(labels):
        _strs(w, lab, f"{path}.labels[{i}]")
    _ints(w, _get(w, s, "terminal", path), f"{path}.terminal", 0, n)
    _bits(w, _get(w, s, "restrictable", path), f"{path}.restrictable", m)
    places = _list(w, _get(w, s, "places", path), f"{path}.places")
    for i, p in enumerate(places):
        if not isinstance(p, str):
            _cell(w, p, f"{path}.places[{i}]")
    _ints(w, _get(w, s, "place", path), f"{path}.place", 0, len(places), n)
    layout = s.get("layout")
    if layout is not None:
        lay = _dict(w, layout, f"{path}.layout")
        rows = _int(w, _get(w, lay, "rows", f"{path}.layout"), f"{path}.layout.rows", 1)
        cols = _int(w, _get(w, lay, "cols", f"{path}.layout"), f"{path}.layout.cols", 1)
        for i, c in enumerate(_list(w, _get(w, lay, "blocked", f"{path}.layout"), f"{path}.layout.blocked")):
            c = _list(w, c, f"{path}.layout.blocked[{i}]", 2)
            _int(w, c[0], f"{path}.layout.blocked[{i}][0]", 0, rows)
            _int(w, c[1], f"{path}.layout.blocked[{i}][1]", 0, cols)
        for i, t in enumerate(_list(w, _get(w, lay, "tokens", f"{path}.layout"), f"{path}.layout.tokens")):
            t = _list(w, t, f"{path}.layout.tokens[{i}]", 3)
            _int(w, t[0], f"{path}.layout.tokens[{i}][0]", 0, rows)
            _int(w, t[1], f"{path}.layout.tokens[{i}][1]", 0, cols)
            _str(w, t[2], f"{path}.layout.tokens[{i}][2]")
    if kind in ("grid", "fuel") and layout is not None:  # a grid with its map plays the grid's moves
        for i, a in enumerate(action):
            if a not in GRID_MOVE_NAMES:
                raise w.fail(f"{path}.action[{i}]", f"{a!r} is not a move of a grid ({', '.join(GRID_MOVE_NAMES)})")
    fuel = s.get("max_fuel")
    if fuel is not None:
        _int(w, fuel, f"{path}.max_fuel", 0)
    return n, m, len(places)


def _dba(w: _Where, d: Any, path: str, n_letters: int, parts: list[int] | None = None) -> int:
    """Check one automaton table; return its number of states."""
    d = _dict(w, d, path)
    delta = _list(w, _get(w, d, "delta", path), f"{path}.delta")
    nq = len(delta)
    if nq == 0:
        raise w.fail(f"{path}.delta", "is empty")
    for i, row in enumerate(delta):
        _ints(w, row, f"{path}.delta[{i}]", 0, nq, n_letters)
    _int(w, _get(w, d, "initial", path), f"{path}.initial", 0, nq)
    acc = _list(w, _get(w, d, "accepting", path), f"{path}.accepting", nq)
    width = None
    for i, row in enumerate(acc):
        row = _list(w, row, f"{path}.accepting[{i}]", width)
        width = len(row) if width is None else width
        _bits(w, row, f"{path}.accepting[{i}]", width)
    _strs(w, _get(w, d, "names", path), f"{path}.names", nq)
    comps = d.get("components")
    if parts is not None:
        if comps is None:
            raise w.fail(f"{path}.components", "missing")
        comps = _list(w, comps, f"{path}.components", nq)
        for i, row in enumerate(comps):
            row = _list(w, row, f"{path}.components[{i}]", len(parts))
            for j, (x, k) in enumerate(zip(row, parts, strict=True)):
                _int(w, x, f"{path}.components[{i}][{j}]", 0, k)
    elif comps is not None:
        for i, row in enumerate(_list(w, comps, f"{path}.components", nq)):
            _ints(w, row, f"{path}.components[{i}]", 0, None)
    return nq


def _strategy(w: _Where, d: Any, path: str, n_hist: int, n_moves: int) -> None:
    d = _dict(w, d, path)
    setting = _get(w, d, "setting", path)
    if setting not in SETTINGS:
        raise w.fail(f"{path}.setting", f"{setting!r} is not one of {', '.join(SETTINGS)}")
    got = _int(w, _get(w, d, "n_hist", path), f"{path}.n_hist", 1)
    if got != n_hist:
        raise w.fail(f"{path}.n_hist", f"is {got}, but automata.histories has {n_hist} states")
    got = _int(w, _get(w, d, "n_moves", path), f"{path}.n_moves", 0)
    if got != n_moves:
        raise w.fail(f"{path}.n_moves", f"is {got}, but the system has {n_moves} moves")
    _ints(w, _get(w, d, "static_obstacles", path), f"{path}.static_obstacles", 0, n_moves)
    restr = _dict(w, _get(w, d, "restrictions", path), f"{path}.restrictions")
    for q, moves in restr.items():
        if not re.fullmatch(r"0|[1-9][0-9]*", q) or int(q) >= n_hist:
            raise w.fail(f"{path}.restrictions", f"history {q!r} is not one of 0..{n_hist - 1}")
        _ints(w, moves, f"{path}.restrictions[{q}]", 0, n_moves)


def _controller(w: _Where, d: Any, path: str, n_hist: int, n_states: int, n_places: int) -> None:
    d = _dict(w, d, path)
    first = _get(w, d, "first", path)
    if first not in ("system", "agent"):
        raise w.fail(f"{path}.first", f"{first!r} is neither 'system' nor 'agent'")
    names = _strs(w, _get(w, d, "agent_names", path), f"{path}.agent_names")
    na = len(names)
    if na == 0:
        raise w.fail(f"{path}.agent_names", "is empty")
    places = _list(w, _get(w, d, "agent_places", path), f"{path}.agent_places", na)
    for i, p in enumerate(places):
        if p is not None:
            _int(w, p, f"{path}.agent_places[{i}]", 0, n_places)
    _int(w, _get(w, d, "initial_agent", path), f"{path}.initial_agent", 0, na)
    n_mem = _int(w, _get(w, d, "n_memory", path), f"{path}.n_memory", 1)
    _int(w, _get(w, d, "initial_memory", path), f"{path}.initial_memory", 0, n_mem)
    got = _int(w, _get(w, d, "n_hist", path), f"{path}.n_hist", 1)
    if got != n_hist:
        raise w.fail(f"{path}.n_hist", f"is {got}, but automata.histories has {n_hist} states")
    got = _int(w, _get(w, d, "n_system_states", path), f"{path}.n_system_states", 1)
    if got != n_states:
        raise w.fail(f"{path}.n_system_states", f"is {got}, but the system has {n_states} states")
    rows = _list(w, _get(w, d, "rows", path), f"{path}.rows")
    seen: set[tuple[int, int]] = set()
    for i, r in enumerate(rows):
        r = _list(w, r, f"{path}.rows[{i}]", 2)
        _int(w, r[0], f"{path}.rows[{i}][0]", 0, n_states)
        _int(w, r[1], f"{path}.rows[{i}][1]", 0, n_hist)
        if (r[0], r[1]) in seen:
            raise w.fail(f"{path}.rows[{i}]", f"{r} is listed twice")
        seen.add((r[0], r[1]))
    table = _dict(w, _get(w, d, "table", path), f"{path}.table")
    length = None
    for key, hi in (("memory", n_mem), ("row", len(rows)), ("agent", na), ("next_agent", na), ("next_memory", n_mem)):
        col = _list(w, _get(w, table, key, f"{path}.table"), f"{path}.table.{key}", length)
        length = len(col)
        _ints(w, col, f"{path}.table.{key}", 0, hi)
    fallback = _list(w, _get(w, d, "fallback", path), f"{path}.fallback", na)
    for i, row in enumerate(fallback):
        _ints(w, row, f"{path}.fallback[{i}]", 0, na, n_places)
    _ints(w, _get(w, d, "sys_place", path), f"{path}.sys_place", 0, n_places, n_states)


def _agent(w: _Where, d: Any, path: str, n_hist: int, n_states: int, n_places: int) -> None:
    d = _dict(w, d, path)
    _controller(w, _get(w, d, "controller", path), f"{path}.controller", n_hist, n_states, n_places)
    na = len(d["controller"]["agent_names"])
    for i, mv in enumerate(_list(w, d.get("moves", []), f"{path}.moves")):
        _ints(w, mv, f"{path}.moves[{i}]", 0, na, 2)
    if "names" in d:
        _strs(w, d["names"], f"{path}.names")


def validate_artifact(d: Any, source: str, fmt: str, version: int) -> None:
    """Check every field of an artifact's plain data (raises :class:`ProblemError` naming it)."""
    w = _Where(source)
    if not isinstance(d, dict):
        raise ProblemError(f"{source} is not a FlowTest test artifact (not a JSON object)")
    if d.get("format") != fmt:
        raise ProblemError(f"{source} is not a FlowTest test artifact (format {d.get('format')!r})")
    if d.get("version") != version:
        raise ProblemError(f"{source} has artifact version {d.get('version')!r}, this FlowTest reads {version}")
    name = _str(w, _get(w, d, "name", ""), "name")
    if not name:
        raise w.fail("name", "is empty")
    kind = _get(w, d, "kind", "")
    if kind not in KINDS:
        raise w.fail("kind", f"{kind!r} is not one of {', '.join(KINDS)}")
    obj = _dict(w, _get(w, d, "objectives", ""), "objectives")
    _str(w, _get(w, obj, "system", "objectives"), "objectives.system")
    _str(w, _get(w, obj, "test", "objectives"), "objectives.test")
    n, m, n_places = _system(w, _get(w, d, "system", ""), "system")
    letters = _list(w, _get(w, d, "letters", ""), "letters")
    for i, a in enumerate(letters):
        _strs(w, a, f"letters[{i}]")
    if not letters:
        raise w.fail("letters", "is empty")
    alphabet = {frozenset(a) for a in letters}
    for i, lab in enumerate(d["system"]["labels"]):
        if frozenset(lab) not in alphabet:
            raise w.fail(f"system.labels[{i}]", f"{sorted(lab)} is not one of the letters")
    auto = _dict(w, _get(w, d, "automata", ""), "automata")
    n_sys = _dba(w, _get(w, auto, "system", "automata"), "automata.system", len(letters))
    n_test = _dba(w, _get(w, auto, "test", "automata"), "automata.test", len(letters))
    n_hist = _dba(w, _get(w, auto, "histories", "automata"), "automata.histories", len(letters), [n_sys, n_test])
    _strategy(w, _get(w, d, "strategy", ""), "strategy", n_hist, m)
    agent = d.get("agent")
    if kind == "agent":
        if agent is None:
            raise w.fail("agent", "missing: an agent test needs its test agent")
        _agent(w, agent, "agent", n_hist, n, n_places)
    elif agent is not None:
        raise w.fail("agent", f"a {kind} test has no test agent")
    summary = _dict(w, _get(w, d, "summary", ""), "summary")
    _int(w, _get(w, summary, "flow", "summary"), "summary.flow", 1)
    extras = _dict(w, d.get("extras", {}), "extras")
    descr = extras.get("history_descriptions")
    if descr is not None:
        _strs(w, descr, "extras.history_descriptions", n_hist)
    area = extras.get("static_moves")
    if area is not None:
        if kind != "mixed":
            raise w.fail("extras.static_moves", f"a {kind} test has no static area typed in (mixed tests only)")
        moves = _ints(w, area, "extras.static_moves", 0, m)
        if len(set(moves)) != len(moves) or moves != sorted(moves):
            raise w.fail("extras.static_moves", "is not a list of move indices in increasing order, each once")
    src = _dict(w, _get(w, d, "source", ""), "source")
    digest = _get(w, src, "sha256", "source")
    if not isinstance(digest, str) or not _HEX64.fullmatch(digest):
        raise w.fail("source.sha256", "is not a SHA-256 hex digest")


# --------------------------------------------------------------------------- JSON Schema

SCHEMA_VERSION = 1
"""The artifact version (the ``version`` field) the JSON Schema of :func:`json_schema` describes."""

SCHEMA_ID = f"urn:flowtest:test-artifact:{SCHEMA_VERSION}"


def json_schema() -> dict[str, Any]:
    """The artifact as a JSON Schema document (draft 2020-12), for readers outside Python.

    It states every field's type and shape, what :func:`validate_artifact` checks field by
    field; what JSON Schema cannot say (an index below the length of another field, the
    automata of the objectives, the source hash, the digest of the content) is checked by
    FlowTest on load and explained in docs/artifact-schema.md. ``docs/artifact-schema.json``
    is this document; ``python -m synthesis.artifacts.schema`` prints it.

    It is written for the strictest readers: Ajv's strict mode (every keyword beside the
    ``type`` it applies to, no union types, tuples closed with ``items: false``, every
    ``required`` name declared in the same ``properties``) as well as Python's
    ``jsonschema`` (tests/synthesis/test_artifact_schema.py runs both).

    >>> json_schema()["properties"]["version"]
    {'const': 1}
    >>> json_schema()["$defs"]["grid_action"]
    {'enum': ['N', 'S', 'E', 'W']}
    """
    nat = {"type": "integer", "minimum": 0}
    bit = {"enum": [0, 1]}
    hex64 = {"type": "string", "pattern": "^[0-9a-f]{64}$"}

    def array(items: dict[str, Any], **more: Any) -> dict[str, Any]:
        return {"type": "array", "items": items, **more}

    def pair(first: dict[str, Any], second: dict[str, Any]) -> dict[str, Any]:
        """A closed tuple of two: Ajv's strictTuples wants ``items: false`` and both bounds."""
        return {"type": "array", "prefixItems": [first, second], "items": False, "minItems": 2, "maxItems": 2}

    def obj(required: dict[str, Any], optional: dict[str, Any] | None = None, closed: bool = True) -> dict[str, Any]:
        out: dict[str, Any] = {"type": "object", "required": list(required), "properties": {**required, **(optional or {})}}
        if closed:
            out["additionalProperties"] = False
        return out

    def when(condition: dict[str, Any], then: dict[str, Any], otherwise: dict[str, Any] | None = None) -> dict[str, Any]:
        """``if`` the object's fields match ``condition``, its fields match ``then`` (else ``otherwise``)."""
        out: dict[str, Any] = {"if": {"type": "object", "properties": condition}, "then": {"type": "object", "properties": then}}
        if otherwise is not None:
            out["else"] = {"type": "object", "properties": otherwise}
        return out

    cell = pair(nat, nat)
    fuel_state = pair({"$ref": "#/$defs/cell"}, nat)
    system = obj(
        {
            "kind": {"enum": list(SYSTEM_KINDS)},
            "states": array({"anyOf": [{"type": "string"}, {"type": "array"}]}, minItems=1),
            "moves": array(pair(nat, nat)),
            "action": array({"anyOf": [{"type": "string"}, {"type": "integer"}]}),
            "stay": array(bit),
            "initial": nat,
            "labels": array(array({"type": "string"})),
            "terminal": array(nat),
            "restrictable": array(bit),
            "places": array({"anyOf": [{"type": "string"}, {"$ref": "#/$defs/cell"}]}),
            "place": array(nat),
        },
        {
            "layout": {
                "anyOf": [
                    {"type": "null"},
                    obj(
                        {
                            "rows": {"type": "integer", "minimum": 1},
                            "cols": {"type": "integer", "minimum": 1},
                            "blocked": array({"$ref": "#/$defs/cell"}),
                            "tokens": array({"type": "array", "prefixItems": [nat, nat, {"type": "string"}], "items": False, "minItems": 3, "maxItems": 3}),
                        }
                    ),
                ]
            },
            "max_fuel": {"anyOf": [{"type": "null"}, nat]},
        },
    )
    system["allOf"] = [
        when({"kind": {"const": "grid"}}, {"states": array({"$ref": "#/$defs/cell"})}),
        when({"kind": {"const": "fuel"}}, {"states": array(fuel_state)}),
        when({"kind": {"const": "graph"}}, {"states": array({"type": "string"})}),
        # a grid with its map plays the grid's moves (action slots 0-3: flowtest_env.game.GRID_ACTIONS)
        when({"kind": {"enum": ["grid", "fuel"]}, "layout": {"type": "object"}}, {"action": array({"$ref": "#/$defs/grid_action"})}),
    ]

    def automaton(components: dict[str, Any]) -> dict[str, Any]:
        return obj(
            {
                "delta": array(array(nat), minItems=1),
                "initial": nat,
                "accepting": array(array(bit)),
                "names": array({"type": "string"}),
            },
            {"components": components},
        )

    controller = obj(
        {
            "format": {"const": "flowtest.agent-controller"},
            "version": {"const": 1},
            "first": {"enum": ["system", "agent"]},
            "agent_names": array({"type": "string"}, minItems=1),
            "agent_places": array({"anyOf": [{"type": "null"}, nat]}),
            "initial_agent": nat,
            "initial_memory": nat,
            "n_memory": {"type": "integer", "minimum": 1},
            "n_hist": {"type": "integer", "minimum": 1},
            "n_system_states": {"type": "integer", "minimum": 1},
            "rows": array(pair(nat, nat)),
            "table": obj({key: array(nat) for key in ("memory", "row", "agent", "next_agent", "next_memory")}),
            "fallback": array(array(nat)),
            "sys_place": array(nat),
        }
    )
    agent = obj(
        {"controller": controller},
        {
            "moves": array(pair(nat, nat)),
            "names": array({"type": "string"}),
            "cells": array({"$ref": "#/$defs/cell"}),
            "parks": array({"type": "object"}),
            "start": {"type": "string"},
            "first": {"enum": ["system", "agent"]},
            "counterexamples": nat,
        },
        closed=False,
    )
    agent_test = when({"kind": {"const": "agent"}}, {"agent": {"$ref": "#/$defs/agent"}}, {"agent": {"type": "null"}})
    agent_test["then"]["required"] = ["agent"]
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": SCHEMA_ID,
        "title": "FlowTest test artifact",
        "description": "A synthesized FlowTest test, as flowtest synthesize --out writes it (docs/artifact-schema.md).",
        "type": "object",
        "required": ["format", "version", "name", "kind", "objectives", "system", "letters", "automata", "strategy", "summary", "source"],
        "additionalProperties": False,
        "properties": {
            "format": {"const": "flowtest-test"},
            "version": {"const": SCHEMA_VERSION},
            "name": {"type": "string", "minLength": 1},
            "kind": {"enum": list(KINDS)},
            "objectives": obj({"system": {"type": "string"}, "test": {"type": "string"}}, closed=False),
            "system": {"$ref": "#/$defs/system"},
            "letters": array(array({"type": "string"}), minItems=1),
            "automata": obj(
                {
                    "system": automaton({"anyOf": [{"type": "null"}, array(array(nat))]}),
                    "test": automaton({"anyOf": [{"type": "null"}, array(array(nat))]}),
                    "histories": automaton(array(pair(nat, nat))),
                }
            ),
            "strategy": obj(
                {
                    "setting": {"enum": list(SETTINGS)},
                    "n_hist": {"type": "integer", "minimum": 1},
                    "n_moves": nat,
                    "static_obstacles": array(nat),
                    "restrictions": {"type": "object", "propertyNames": {"type": "string", "pattern": "^(0|[1-9][0-9]*)$"}, "additionalProperties": array(nat)},
                }
            ),
            "agent": {"anyOf": [{"type": "null"}, {"$ref": "#/$defs/agent"}]},
            "summary": {"type": "object", "required": ["flow"], "properties": {"flow": {"type": "integer", "minimum": 1}}},
            "extras": {"type": "object", "properties": {"history_descriptions": array({"type": "string"}), "static_moves": array(nat, uniqueItems=True)}},
            "source": obj({"sha256": hex64}),
            "digest": obj({"sha256": hex64}),
        },
        "allOf": [
            agent_test,
            # only a mixed test carries the static area typed in
            when({"kind": {"const": "mixed"}}, {}, {"extras": {"type": "object", "properties": {"static_moves": False}}}),
        ],
        "$defs": {"cell": cell, "grid_action": {"enum": list(GRID_MOVE_NAMES)}, "system": system, "agent": agent},
    }


if __name__ == "__main__":  # pragma: no cover - python -m synthesis.artifacts.schema
    sys.stdout.write(json.dumps(json_schema(), indent=1) + "\n")
