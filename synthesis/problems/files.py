"""Problem files (problem-format.md): TOML read into a :class:`~synthesis.problems.problem.Problem`.

Every section is checked for unknown keys and bad values; a mistake is one
:class:`~synthesis.model.errors.ProblemError` naming what and where. Input files are read
through :func:`read_limited` (regular files up to :data:`MAX_FILE_BYTES`).
"""

from __future__ import annotations

import os
import re
import stat
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ..model.errors import ProblemError, ProblemTooLarge
from ..model.option_rules import FLAG, SECONDS, SETTING
from ..model.specs import check_proposition_name
from ..model.systems import Cell, TransitionSystem, graph_system, grid_world
from .agent_section import agent_from_toml
from .problem import CAP_KEYS, KINDS, Problem, check_caps, make_problem

_TOP_KEYS = {"name", "description", "system", "labels", "objectives", "environment"}
_GRID_KEYS = {"grid", "start", "terminal", "restrictable"}
_GRAPH_KEYS = {"states", "edges", "start", "terminal", "stay", "restrictable"}
_OBJ_KEYS = {"system", "test"}
_ENV_KEYS = {"kind", "static", "bidirectional_cuts", "time_limit", "setting", "agent", "one_way_walls", *CAP_KEYS}


def _unknown(section: str, got: dict[str, Any], allowed: set[str]) -> None:
    extra = sorted(set(got) - allowed)
    if extra:
        raise ProblemError(f"unknown key {extra[0]!r} in {section} (allowed: {', '.join(sorted(allowed))})")


def _is_int(x: Any) -> bool:
    """An integer that is not a boolean (TOML's ``true`` is not the number 1)."""
    return isinstance(x, int) and not isinstance(x, bool)


def _is_cell(x: Any) -> bool:
    return isinstance(x, list) and len(x) == 2 and all(_is_int(v) for v in x)


_TOKEN_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def _table(d: dict[str, Any], key: str, where: str) -> dict[str, Any]:
    v = d.get(key)
    if v is None:
        raise ProblemError(f"missing section [{key}]{where}")
    if not isinstance(v, dict):
        raise ProblemError(f"[{key}] must be a table{where}")
    return v


MAX_GRID_CELLS = 125_000
"""Largest grid loaded by default (about 350x350): beyond it the moves alone (about four per
cell, times at least two histories) pass the product-graph limit of :mod:`synthesis.problems.limits`,
and building T itself takes long. ``max_cells=None`` (``--no-size-limit``) lifts it."""


def parse_grid(text: str, where: str = "[system] grid", max_cells: int | None = MAX_GRID_CELLS) -> tuple[list[list[str]], int, int]:
    """Split grid text into rows of tokens; all rows must have the same width.

    Raises
    ------
    ProblemError
        On ragged rows, a token that is not a name, or more than ``max_cells`` cells.
    """
    if not isinstance(text, str):
        raise ProblemError(f"{where} must be a string of whitespace-separated tokens")
    rows = [line.split() for line in text.strip("\n").splitlines() if line.strip()]
    if not rows:
        raise ProblemError(f"{where} is empty")
    width = len(rows[0])
    if max_cells is not None and len(rows) * width > max_cells:
        raise ProblemTooLarge(
            f"{where} has {len(rows)}x{width} = {len(rows) * width} cells, more than the {max_cells} that can be "
            "synthesized (its product graph alone would exceed the size limit); pass --no-size-limit to try anyway"
        )
    for i, r in enumerate(rows):
        if len(r) != width:
            raise ProblemError(f"{where}: row {i} has {len(r)} cells, row 0 has {width}")
        for j, tok in enumerate(r):
            if tok not in (".", "#") and _TOKEN_NAME.fullmatch(tok) is None:
                raise ProblemError(f"{where}: the token {tok!r} at [{i}, {j}] is not '.', '#' or a name (letters, digits and _, not starting with a digit)")
    return rows, len(rows), width


def _cells_of(spec: Any, tokens: dict[str, list[Cell]], where: str, rows: int, cols: int) -> list[Cell]:
    """Resolve a token name, a ``[row, col]`` cell, or a list of them."""
    if isinstance(spec, str):
        if spec not in tokens:
            raise ProblemError(f"{where}: no cell of the grid holds token {spec!r}")
        return list(tokens[spec])
    if _is_cell(spec):
        r, c = spec
        if not (0 <= r < rows and 0 <= c < cols):
            raise ProblemError(f"{where}: cell [{r}, {c}] is outside the {rows}x{cols} grid")
        return [(r, c)]
    if isinstance(spec, list):
        out: list[Cell] = []
        for item in spec:
            if isinstance(item, list) and not _is_cell(item):
                raise ProblemError(f"{where}: {item!r} is neither a token nor a [row, col] cell")
            out.extend(_cells_of(item, tokens, where, rows, cols))
        return out
    raise ProblemError(f"{where}: {spec!r} is neither a token nor a [row, col] cell")


def problem_from_dict(data: dict[str, Any], source: str = "<problem>", max_cells: int | None = MAX_GRID_CELLS) -> Problem:
    """Build a problem from the parsed TOML of problem-format.md.

    Every section is checked for unknown keys first, so a misspelled key is named
    (``unknown key 'termnal'``) rather than reported as the key it replaced missing.
    """
    where = f" of {source}"
    _unknown(f"the top level{where}", data, _TOP_KEYS)
    name = data.get("name", Path(source).stem)
    if not isinstance(name, str) or not name.strip() or not name.isprintable():
        raise ProblemError(f"`name`{where} must be a non-empty one-line string")
    description = data.get("description", "")
    if not isinstance(description, str):
        raise ProblemError(f"`description`{where} must be a string")
    system = _table(data, "system", where)
    objectives = _table(data, "objectives", where)
    env = _table(data, "environment", where)
    labels = data.get("labels", {})
    if not isinstance(labels, dict):
        raise ProblemError(f"[labels]{where} must be a table")
    _unknown(f"[objectives]{where}", objectives, _OBJ_KEYS)
    _unknown(f"[environment]{where}", env, _ENV_KEYS)
    if "grid" in system:
        _unknown(f"[system]{where}", system, _GRID_KEYS)
    elif "states" in system:
        _unknown(f"[system]{where}", system, _GRAPH_KEYS)
    else:
        _unknown(f"[system]{where}", system, _GRID_KEYS | _GRAPH_KEYS)
    for prop in labels:
        check_proposition_name(prop, f"[labels]{where}")
    for key in ("system", "test"):
        if key not in objectives:
            raise ProblemError(f"missing `{key}` in [objectives]{where}")
    if "kind" not in env:
        raise ProblemError(f"missing `kind` in [environment]{where}")
    kind = env["kind"]
    if not isinstance(kind, str) or kind not in KINDS:
        raise ProblemError(f"`kind` in [environment]{where} is {kind!r}; expected one of {', '.join(KINDS)}")
    for key in ("start", "terminal"):
        if key not in system:
            raise ProblemError(f"missing `{key}` in [system]{where}")
    # the solver options a problem file may hold follow the rules the Python options and the
    # command line follow (synthesis.model.option_rules): the same bad value, the same reason
    time_limit = SECONDS.check(env.get("time_limit"), f"`time_limit` in [environment]{where}")
    bidir = env.get("bidirectional_cuts")
    if bidir is not None:
        FLAG.check(bidir, f"`bidirectional_cuts` in [environment]{where}")
    if "setting" in env:
        SETTING.check(env["setting"], f"`setting` in [environment]{where}")
    if "static" in env and kind not in ("mixed", "agent"):
        raise ProblemError(f"`static` in [environment]{where} is for mixed and agent problems, not {kind!r} ones")
    if "agent" in env and kind != "agent":
        raise ProblemError(f'[environment.agent]{where} is for kind = "agent" problems, not {kind!r} ones')
    if "grid" in system:
        ts, cell_of = _grid_from_toml(system, labels, where, max_cells)
    elif "states" in system:
        ts, cell_of = _graph_from_toml(system, labels, where)
    else:
        raise ProblemError(f"[system]{where} needs either `grid` or `states` and `edges`")
    static_moves = None
    if "static" in env:
        static_moves = _moves_mask(ts, env["static"], cell_of, f"[environment] static{where}")
    if "restrictable" in system:
        ts.restrictable = _moves_mask(ts, system["restrictable"], cell_of, f"[system] restrictable{where}")
    extras: dict[str, Any] = {}
    if "setting" in env:
        extras["setting"] = env["setting"]
    caps = check_caps({k: env[k] for k in CAP_KEYS if k in env}, f" in [environment]{where}")
    one_way = env.get("one_way_walls", kind == "static" and bidir is False)
    FLAG.check(one_way, f"`one_way_walls` in [environment]{where}")
    kw: dict[str, Any] = {
        "static_moves": static_moves,
        "time_limit": time_limit,
        "extras": extras,
        "caps": caps,
        "one_way_walls": one_way,
    }
    if "agent" in env:
        kw["agent"] = agent_from_toml(env["agent"], ts, cell_of, f"[environment.agent]{where}")
    elif kind == "agent":
        raise ProblemError(f"an agent problem needs an [environment.agent] section{where}")
    kw["declared_propositions"] = set(labels)
    return make_problem(name, ts, objectives["system"], objectives["test"], kind, bidir, description=description, **kw)


def _grid_from_toml(
    system: dict[str, Any], labels: dict[str, Any], where: str, max_cells: int | None = MAX_GRID_CELLS
) -> tuple[TransitionSystem, Callable[[Any, str], list[int]]]:
    rows, n_rows, n_cols = parse_grid(system["grid"], f"[system] grid{where}", max_cells)
    tokens: dict[str, list[Cell]] = {}
    free: list[Cell] = []
    named: dict[Cell, str] = {}
    for r, row in enumerate(rows):
        for c, tok in enumerate(row):
            if tok == "#":
                continue
            free.append((r, c))
            if tok != ".":
                tokens.setdefault(tok, []).append((r, c))
                named[(r, c)] = tok
    if not free:
        raise ProblemError(f"[system] grid{where} has no free cell")
    start_cells = _cells_of(system["start"], tokens, f"[system] start{where}", n_rows, n_cols)
    if len(start_cells) != 1:
        raise ProblemError(f"[system] start{where} must name exactly one cell, got {len(start_cells)}")
    start = start_cells[0]
    if start not in set(free):
        raise ProblemError(f"[system] start{where}: cell {list(start)} is blocked")
    terminal = _cells_of(system["terminal"], tokens, f"[system] terminal{where}", n_rows, n_cols)
    if not terminal:
        raise ProblemError(f"[system] terminal{where} is empty: a test must be able to end")
    free_set = set(free)
    for cell in terminal:
        if cell not in free_set:
            raise ProblemError(f"[system] terminal{where}: cell {list(cell)} is blocked")
    lab: dict[Cell, set[str]] = {}
    for prop, spec in labels.items():
        for cell in _cells_of(spec, tokens, f"[labels] {prop}{where}", n_rows, n_cols):
            if cell not in free_set:
                raise ProblemError(f"[labels] {prop}{where}: cell {list(cell)} is blocked")
            lab.setdefault(cell, set()).add(prop)
    ts = grid_world(free, n_rows, n_cols, start, terminal, lab, named)

    def cell_of(spec: Any, at: str) -> list[int]:
        cells = _cells_of(spec, tokens, at, n_rows, n_cols)
        out = []
        for c in cells:
            if c not in free_set:
                raise ProblemError(f"{at}: cell {list(c)} is blocked")
            out.append(ts.index(c))
        return out

    return ts, cell_of


def _graph_from_toml(system: dict[str, Any], labels: dict[str, Any], where: str) -> tuple[TransitionSystem, Callable[[Any, str], list[int]]]:
    states = system["states"]
    if not isinstance(states, list) or not all(isinstance(s, str) and s.strip() and s.isprintable() for s in states):
        raise ProblemError(f"[system] states{where} must be a list of state names (non-empty one-line strings)")
    if not states:
        raise ProblemError(f"[system] states{where} is empty")
    edges = system.get("edges", [])
    if not isinstance(edges, list) or not all(isinstance(e, list) and len(e) == 2 and all(isinstance(x, str) for x in e) for e in edges):
        raise ProblemError(f"[system] edges{where} must be a list of [from, to] state-name pairs")
    start = system["start"]
    if not isinstance(start, str):
        raise ProblemError(f"[system] start{where} must be a state name")
    terminal = system["terminal"]
    if isinstance(terminal, str):
        terminal = [terminal]
    if not isinstance(terminal, list) or not terminal or not all(isinstance(t, str) for t in terminal):
        raise ProblemError(f"[system] terminal{where} must be a non-empty list of state names")
    lab: dict[str, set[str]] = {}
    known = set(states)
    for prop, spec in labels.items():
        names = [spec] if isinstance(spec, str) else spec
        if not isinstance(names, list) or not all(isinstance(s, str) for s in names):
            raise ProblemError(f"[labels] {prop}{where} must be a state name or a list of them")
        for s in names:
            if s not in known:
                raise ProblemError(f"[labels] {prop}{where}: unknown state {s!r}")
            lab.setdefault(s, set()).add(prop)
    stay = system.get("stay", True)
    if not isinstance(stay, bool):
        raise ProblemError(f"[system] stay{where} must be true or false")
    ts = graph_system(states, [tuple(e) for e in edges], start, terminal, lab, stay)

    def cell_of(spec: Any, at: str) -> list[int]:
        names = [spec] if isinstance(spec, str) else spec
        if not isinstance(names, list):
            raise ProblemError(f"{at}: {spec!r} is neither a state name nor a list of them")
        out = []
        for s in names:
            if not isinstance(s, str) or s not in known:
                raise ProblemError(f"{at}: unknown state {s!r}")
            out.append(ts.index(s))
        return out

    return ts, cell_of


def _moves_mask(ts: TransitionSystem, spec: Any, cell_of: Callable[[Any, str], list[int]], where: str) -> np.ndarray:
    """A list of transitions ``[from, to]`` (cells, tokens or state names) as a move mask."""
    if not isinstance(spec, list):
        raise ProblemError(f"{where} must be a list of [from, to] transitions")
    index = ts.move_index()
    mask = np.zeros(ts.n_moves, dtype=bool)
    for item in spec:
        if not (isinstance(item, list) and len(item) == 2):
            raise ProblemError(f"{where}: {item!r} is not a [from, to] transition")
        for a in cell_of(item[0], where):
            for b in cell_of(item[1], where):
                e = index.get((a, b))
                if e is None:
                    raise ProblemError(f"{where}: there is no move from {ts.states[a]} to {ts.states[b]}")
                mask[e] = True
    return mask


MAX_FILE_BYTES = 16 * 1024 * 1024
"""Largest input file read (problem files, artifacts): far above any solvable problem."""


def read_limited(path: str | Path, what: str, limit: int = MAX_FILE_BYTES) -> bytes:
    """The bytes of a regular file of at most ``limit`` bytes.

    Raises
    ------
    ProblemError
        If ``path`` cannot be read, is not a regular file (a folder, ``/dev/zero``, a
        pipe: reading it could never end) or is larger than ``limit``.
    """
    p = Path(path)
    try:
        # non-blocking open: a named pipe must not hang the check below
        fd = os.open(p, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
        with os.fdopen(fd, "rb") as fh:
            if not stat.S_ISREG(os.fstat(fd).st_mode):
                raise ProblemError(f"{what} {str(p)!r} is not a regular file")
            raw = fh.read(limit + 1)
    except OSError as exc:
        raise ProblemError(f"cannot read {what} {str(p)!r}: {exc.strerror or exc}") from None
    if len(raw) > limit:
        raise ProblemError(f"{what} {str(p)!r} is larger than {limit // (1024 * 1024)} MiB")
    return raw


def _first_line(exc: BaseException) -> str:
    """The first line of an exception's message, at most 200 characters."""
    text = (str(exc).splitlines() or [type(exc).__name__])[0]
    return text if len(text) <= 200 else text[:197] + "..."


def load_problem_file(path: str | Path, max_cells: int | None = MAX_GRID_CELLS) -> Problem:
    """Read a TOML problem file.

    Raises
    ------
    ProblemError
        If the file cannot be read or parsed, or describes an invalid problem.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> from synthesis import load_problem_file
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = pathlib.Path(folder, "corridor.toml")
    ...     _ = path.write_text('''
    ... name = "corridor"
    ... [system]
    ... grid = "S . A . T"
    ... start = "S"
    ... terminal = ["T"]
    ... [labels]
    ... goal = ["T"]
    ... a = ["A"]
    ... [objectives]
    ... system = "F goal"
    ... test = "F a"
    ... [environment]
    ... kind = "static"
    ... ''')
    ...     problem = load_problem_file(path)
    >>> problem.name, problem.kind, problem.system.n_states
    ('corridor', 'static', 5)
    """
    p = Path(path)
    raw = read_limited(p, "problem file")
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except UnicodeDecodeError:
        raise ProblemError(f"problem file {str(p)!r} is not UTF-8 text") from None
    except tomllib.TOMLDecodeError as exc:
        raise ProblemError(f"{p}: invalid TOML: {exc}") from None
    except RecursionError:
        raise ProblemError(f"{p}: invalid TOML: nested too deeply") from None
    except ValueError as exc:  # an integer of thousands of digits (int's digit limit), a bad date
        if "digits" in str(exc):
            raise ProblemError(f"{p}: invalid TOML: an integer has more digits than Python reads (at most 4300)") from None
        raise ProblemError(f"{p}: invalid TOML: {_first_line(exc)}") from None
    return problem_from_dict(data, str(p), max_cells)
