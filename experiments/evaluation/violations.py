"""What broke in a violated run: the conjunct of the system objective, the step and the cell.

:func:`violation_of` finds the first step of a run from which one conjunct of the system
objective, on its own, can no longer be met past the static walls, and names it in the
user's own words; the report's cards and the filmstrips both show it (a module of its own,
so that neither imports the other).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class Violation:
    """Which conjunct of the system objective a run broke, at which step and where.

    ``conjunct`` is the conjunct as the problem writes it (``G !hazard``), or the whole
    objective when no conjunct alone is broken (together they can no longer be met,
    ``alone`` false); ``kind`` is its task kind (``safety``, ``visit``, ...); ``step``
    counts SUT steps (0: at reset); ``where`` is the cell (``(3, 4)``), with the fuel on
    fuel grids, or the state's name on graphs."""

    conjunct: str
    step: int
    where: str
    kind: str = ""
    alone: bool = True

    def text(self, steps: str | None = None) -> str:
        """``broke G !hazard at step 7 in cell (3, 4)``; for a visit, that it can no
        longer be met from there. ``steps`` replaces ``step 7`` (a line that folds several
        runs writes their steps there)."""
        what = self.conjunct if self.alone else f"{self.conjunct} (no conjunct alone: together)"
        out = f"broke {what} at {steps if steps is not None else f'step {self.step}'} {where_words(self.where)}"
        if self.kind in ("visit", "sequenced", "delayed") or not self.alone:
            out += " (it can no longer be met from there)"
        return out

    def to_dict(self) -> dict[str, Any]:
        return {"conjunct": self.conjunct, "kind": self.kind, "step": self.step, "where": self.where, "alone": self.alone, "text": self.text()}


def where_words(where: str) -> str:
    return f"in cell {where}" if where.startswith("(") else f"at {where}"


def written_conjuncts(text: str) -> dict[str, str]:
    """The top-level conjuncts of an objective as written (``"F bay & G !hazard"`` ->
    ``{"F bay": "F bay", "G(!hazard)": "G !hazard"}``), keyed by the parser's text of each
    (:attr:`synthesis.model.specs.Task.text`), so messages quote the user's own words."""
    from synthesis.model.errors import ProblemError
    from synthesis.model.specs import parse_formula, to_text

    pieces, depth, begin = [], 0, 0
    for i, ch in enumerate(text):
        if ch == "(":
            depth += 1
        elif ch == ")":
            depth -= 1
        elif ch == "&" and depth == 0:
            pieces.append(text[begin:i])
            begin = i + 1
    pieces.append(text[begin:])
    out: dict[str, str] = {}
    for piece in pieces:
        try:
            out.setdefault(to_text(parse_formula(piece)), " ".join(piece.split()))
        except ProblemError:
            continue
    return out


def _where(ts: Any, state: int) -> str:
    """A state as the report names it: ``(r, c)``, ``(r, c) with fuel f``, or its name."""
    if ts.kind in ("grid", "fuel") and ts.layout is not None:
        r, c = (int(x) for x in ts.places[int(ts.place[state])])
        if ts.kind == "fuel":
            return f"({r}, {c}) with fuel {int(ts.states[state][1])}"
        return f"({r}, {c})"
    return str(ts.states[state])


def _doomed(ts: Any, walls: np.ndarray, dba: Any, letter: np.ndarray) -> np.ndarray:
    """``bool[n_q, n_states]``: from ``(q, s)`` no run of the system past the static
    ``walls`` reaches an accepting state of ``dba`` (backward reachability)."""
    nq, n = dba.n_states, ts.n_states
    mm = np.flatnonzero(~walls)
    st = np.flatnonzero(ts.stay)
    q = np.arange(nq)[:, None]
    src = np.concatenate([(q * n + ts.src[mm][None, :]).ravel(), (q * n + st[None, :]).ravel()])
    dst = np.concatenate([(dba.delta[:, letter[ts.dst[mm]]] * n + ts.dst[mm][None, :]).ravel(), (dba.delta[:, letter[st]] * n + st[None, :]).ravel()])
    can = np.repeat(dba.accepting[:, 0], n)
    while True:
        grow = src[can[dst] & ~can[src]]
        if grow.size == 0:
            return np.asarray(~can.reshape(nq, n))
        can[grow] = True


def violation_of(artifact: Any, systems: Sequence[int]) -> Violation | None:
    """Which conjunct of ``artifact``'s system objective the run through the system
    states ``systems`` (at reset, then after every step) broke first, and where: the
    first step from which that conjunct alone can no longer be met past the static walls
    (``G !hazard``: the step into the hazard; ``F bay``: the step into a dead end). When no
    conjunct alone is broken, the whole objective at the last step (``alone=False``).
    ``None`` for an empty run.

    Example::

        v = violation_of(game.artifact, [r.system for r in trace.states])
        v.text()  # 'broke G !hazard at step 7 in cell (2, 6)'
    """
    from synthesis.graphs.automata import task_automaton
    from synthesis.model.specs import parse_objective

    if not systems:
        return None
    ts = artifact.system
    text = str(artifact.objectives.get("system", ""))
    letter = ts.letter_of_state(artifact.letters)
    walls = np.asarray(artifact.strategy.static_obstacles, dtype=bool)
    path = [int(s) for s in systems]
    written = written_conjuncts(text)
    best: tuple[int, str, str] | None = None
    for task in parse_objective(text, "system").tasks:
        dba = task_automaton(task, artifact.letters)
        doomed = _doomed(ts, walls, dba, letter)
        qs = int(dba.delta[dba.initial, letter[path[0]]])
        for k, s in enumerate(path):
            if k:
                qs = int(dba.delta[qs, letter[s]])
            if doomed[qs, s]:
                if best is None or k < best[0]:
                    best = (k, written.get(task.text, task.text), task.kind)
                break
    if best is None:
        return Violation(text, len(path) - 1, _where(ts, path[-1]), alone=False)
    return Violation(best[1], best[0], _where(ts, path[best[0]]), best[2])


_GAMES: dict[str, Any] = {}


def violation_of_trace(trace: Any) -> dict[str, Any] | None:
    """:meth:`Violation.to_dict` of a run whose system objective was violated (an
    :class:`experiments.evaluation.episodes.Trace` with its states), else ``None``; what
    ``results.json`` keeps in a failure's ``violation`` and the report shows. The run's
    own game is read (a trace made without one: the test its ``env_id`` names)."""
    if trace.verdict.get("system_objective") != "violated" or not trace.states:
        return None
    game = getattr(trace, "game", None) or _GAMES.get(trace.env_id)
    if game is None:
        from synthesis.model.errors import ProblemError

        from .episodes import env_named

        try:
            env = env_named(trace.env_id)
        except ProblemError:  # not one test (a pool's split): the reason alone is reported
            return None
        game = env.unwrapped.game
        env.close()
        if len(_GAMES) > 64:
            _GAMES.clear()
        _GAMES[trace.env_id] = game
    found = violation_of(game.artifact, [r.system for r in trace.states])
    return None if found is None else found.to_dict()
