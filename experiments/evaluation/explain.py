"""What a failing run did, in the floor's terms: one line per run, alike runs folded.

A report that says only "did not meet the system objective within the step budget" leaves
the engineer to replay the run. :func:`explain` reads a failing run (its states and the game
it was played on) and says what happened:

* a run still **open** when the step budget ran out: the loop it ended in (:func:`find_loop`:
  from which step, between which cells, every how many steps) and, for every move out of the
  loop's cells that leads toward the goal past the static walls, whether the test refused it
  on every visit and why (a door closed under history ``q2``, the test agent standing in
  the way: the causes of the planner protocol, :func:`flowtest_env.runtime.refused_by`) or
  allowed it and the system never took it. A run that never settled into a loop says so,
  and how near the goal it came;
* a **violated** run: the conjunct of the system objective it broke, the step and the cell
  (:func:`experiments.evaluation.violations.violation_of`);
* a planner that failed, or a test failure: its reason.

Histories are named neutrally (``q2``), as ``flowtest serve`` names them: what a history means
gives the hidden test objective away, and the report shows it only behind its "reveal"
switch. :func:`fold` gathers runs that ended the same way into one line with their seeds.

Example::

    from experiments.evaluation.explain import explain, fold

    lines = fold([(t.seed, explain(t)) for t in traces if t.failed])
    lines[0].line()  # 'seeds 0-9 (10 runs): from step 2 on, alternates between (0, 1) and (1, 1) ...'
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

STEPS = "\x00steps\x00"
"""Where a template holds its run's step (``step 2``; a folded line: ``steps 2-18``)."""

LISTED_MOVES = 3
"""How many moves toward the goal a line names (the refused ones first)."""


@dataclass(frozen=True)
class Loop:
    """The periodic end of a run: from step ``start`` on, the system's state repeats every
    ``period`` steps to the end of the run; ``states`` is one round (from ``start``)."""

    start: int
    period: int
    states: tuple[int, ...]
    end: int
    """The run's last step."""

    @property
    def rounds(self) -> float:
        """How many times the round was gone (``(end - start) / period``)."""
        return (self.end - self.start) / self.period


def _periodic_tail(seq: Sequence[Any], min_rounds: int, min_steps: int, max_period: int) -> tuple[int, int] | None:
    """``(start, period)``: the earliest index from which ``seq`` repeats with a period to
    its end, for ``min_rounds`` rounds and ``min_steps`` steps at least; the shortest period."""
    n = len(seq)
    best: tuple[int, int] | None = None
    for p in range(1, min(max_period, n // min_rounds) + 1):
        k = n - p  # the periodic tail seq[k:] with seq[i] == seq[i + p]
        while k > 0 and seq[k - 1] == seq[k - 1 + p]:
            k -= 1
        if n - 1 - k >= max(min_rounds * p, min_steps) and (best is None or k < best[0]):
            best = (k, p)
    return best


def find_loop(systems: Sequence[int], keys: Sequence[Any] | None = None, min_rounds: int = 3, min_steps: int = 8, max_period: int = 64) -> Loop | None:
    """The loop a run ended in, from the system's states (at reset, then after every step):
    the earliest step from which the run repeats itself to the end, for at least
    ``min_rounds`` rounds and ``min_steps`` steps (a few steps alike at the end of a
    wandering run are no loop), and the shortest period of the system's states from there.
    ``keys`` (default the states) tell when the run repeats: the whole run state (the
    system, its history, the test agent), so the loop begins where the test, too, has
    settled. ``None`` if the run did not end in one.

    >>> find_loop([0, 1, 2, 3, 2, 3, 2, 3, 2, 3, 2, 3])
    Loop(start=2, period=2, states=(2, 3), end=11)
    >>> find_loop([0, 1, 2, 3, 4]) is None
    True
    """
    s = list(systems)
    tail = _periodic_tail(list(keys) if keys is not None else s, min_rounds, min_steps, max_period)
    if tail is None:
        return None
    k, period = tail
    p = next(q for q in range(1, period + 1) if period % q == 0 and all(s[i] == s[i + q] for i in range(k, len(s) - q)))
    return Loop(k, p, tuple(s[k : k + p]), len(s) - 1)


@dataclass(frozen=True)
class MoveVerdict:
    """What the test did with one move toward the goal out of a loop's cell, over the
    loop's visits of that cell: refused on ``refused`` of ``visits`` visits, for
    ``causes`` (``door closed under history q2``, ``the test agent stood in the way``)."""

    source: str
    target: str
    action: str
    visits: int
    refused: int
    causes: tuple[str, ...] = ()

    def text(self) -> str:
        """``the move (0, 1) -> (0, 2) was refused on every visit: door closed under history q0``."""
        move = f"the move {self.source} -> {self.target}" if self.source != self.target else f"staying in {self.source}"
        why = f": {' or '.join(self.causes)}" if self.causes else ""
        if self.refused == self.visits:
            return f"{move} was refused on every visit{why}"
        if self.refused == 0:
            return f"{move} toward the goal was allowed on every visit and never taken"
        return f"{move} was refused on {self.refused} of {self.visits} visits{why}, and never taken when allowed"

    def to_dict(self) -> dict[str, Any]:
        return {
            "from": self.source,
            "to": self.target,
            "action": self.action,
            "visits": self.visits,
            "refused": self.refused,
            "causes": list(self.causes),
            "text": self.text(),
        }


@dataclass(frozen=True)
class Explanation:
    """One failing run in the floor's terms: ``text`` (one line), ``what`` (``loop``,
    ``wander``, ``violation``, ``planner``, ``reason``), the step it began at, and the
    ``template`` that runs ending the same way share (their step left out)."""

    what: str
    text: str
    template: str
    step: int | None = None
    loop: Loop | None = None
    cells: tuple[str, ...] = ()
    moves: tuple[MoveVerdict, ...] = ()
    extra: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """What ``results.json`` keeps of it (a failure's ``explanation``)."""
        out: dict[str, Any] = {"what": self.what, "text": self.text, "step": self.step, **self.extra}
        if self.loop is not None:
            out["loop"] = {"from_step": self.loop.start, "period": self.loop.period, "cells": list(self.cells), "rounds": round(self.loop.rounds, 1)}
        if self.moves:
            out["moves"] = [m.to_dict() for m in self.moves]
        return out


def _with_steps(template: str, steps: str) -> str:
    return template.replace(STEPS, steps)


# --------------------------------------------------------------------------- the floor's words


def place_name(game: Any, state: int) -> str:
    """Where a state is, as the report writes it: ``(r, c)`` on grids (the cell, whatever
    the fuel), the state's name on graphs."""
    if game.is_grid:
        r, c = game.cells[int(game.ts.place[state])]
        return f"({r}, {c})"
    return str(game.ts.states[state])


_DISTANCES: dict[int, tuple[Any, np.ndarray]] = {}


def goal_distances(game: Any) -> np.ndarray:
    """``int[n_q, n_states]``: the fewest steps from ``(q, s)`` (the system objective's
    automaton state and the system's state) to meeting the system objective, past the
    static walls only (``-1``: never). Cached per test."""
    art = game.artifact
    hit = _DISTANCES.get(id(art))
    if hit is not None and hit[0] is art:
        return hit[1]
    ts, dba = game.ts, art.system_automaton
    letter = ts.letter_of_state(art.letters)
    nq, n = dba.n_states, ts.n_states
    open_moves = np.flatnonzero(~np.asarray(art.strategy.static_obstacles, dtype=bool))
    stays = np.flatnonzero(ts.stay)
    q = np.arange(nq)[:, None]
    src = np.concatenate([(q * n + ts.src[open_moves][None, :]).ravel(), (q * n + stays[None, :]).ravel()])
    dst = np.concatenate(
        [(dba.delta[:, letter[ts.dst[open_moves]]] * n + ts.dst[open_moves][None, :]).ravel(), (dba.delta[:, letter[stays]] * n + stays[None, :]).ravel()]
    )
    dist = np.where(np.repeat(dba.accepting[:, 0], n), 0, -1).astype(np.int64)
    d = 0
    while True:
        grow = np.unique(src[(dist[dst] == d) & (dist[src] < 0)])
        if grow.size == 0:
            break
        d += 1
        dist[grow] = d
    table = dist.reshape(nq, n)
    if len(_DISTANCES) > 64:
        _DISTANCES.clear()
    _DISTANCES[id(art)] = (art, table)
    return table


def _automaton_state(game: Any, run: Any) -> int:
    """The system objective's automaton state of a run state (its history's system part)."""
    return int(game.q_sys[run.history])


def _cause(game: Any, run: Any, slot: int, tester: str) -> str:
    """Why a move is refused now, as a key :func:`_causes_words` reads: ``agent``,
    ``wall``, ``tester`` or ``door:H`` (closed under history ``H``)."""
    from flowtest_env.runtime import refused_by

    by = refused_by(game, run, slot)
    if by == "door":
        return "tester" if tester != "synthesized" else f"door:{run.history}"
    return by


def _causes_words(causes: Sequence[str]) -> tuple[str, ...]:
    """``door closed under histories q0, q2``, ``the test agent stood in the way``, ..."""
    doors = sorted({int(c.split(":")[1]) for c in causes if c.startswith("door:")})
    out = []
    if doors:
        many = "histories" if len(doors) > 1 else "history"
        out.append(f"door closed under {many} {', '.join(f'q{h}' for h in doors)}")
    words = {"tester": "door closed by the tester", "agent": "the test agent stood in the way", "wall": "a wall"}
    out += [words[c] for c in ("tester", "agent", "wall") if c in causes]
    return tuple(out)


def _moves_toward_goal(game: Any, states: Sequence[Any], loop: Loop, tester: str) -> list[MoveVerdict]:
    """Every move out of the loop's cells that leads toward the goal (fewer steps to meet
    the system objective past the walls), with what the test did to it on each visit."""
    dist = goal_distances(game)
    art = game.artifact
    letter = game.ts.letter_of_state(art.letters)
    delta = art.system_automaton.delta
    inside = {game.place_list[s] for s in loop.states}
    seen: dict[tuple[int, int], list[Any]] = {}  # (state, slot) -> [visits, refused, causes]
    for i in range(loop.start, min(loop.end, len(states) - 1)):  # the visits where the system chose
        run = states[i]
        s, q = int(run.system), _automaton_state(game, run)
        here = dist[q, s]
        if here <= 0:
            continue
        bits = game.restricted_bits_of(run)
        for slot in range(game.n_actions):
            if slot == game.stay_action:
                if not game.ts.stay[s]:
                    continue
                t = s
            else:
                t = game.slot_list[s][slot]
                if t < 0 or game.static_bits[s] >> slot & 1:  # no move, or a wall: not a way
                    continue
                t = int(game.ts.dst[t])
                if game.place_list[t] in inside:
                    continue
            there = dist[int(delta[q, letter[t]]), t]
            if there < 0 or there >= here:
                continue
            entry = seen.setdefault((s, slot), [0, 0, []])
            entry[0] += 1
            if slot != game.stay_action and bits >> slot & 1:
                entry[1] += 1
                cause = _cause(game, run, slot, tester)
                if cause not in entry[2]:
                    entry[2].append(cause)
    verdicts = []
    for (s, slot), (visits, refused, causes) in seen.items():
        t = s if slot == game.stay_action else int(game.ts.dst[game.slot_list[s][slot]])
        verdicts.append(MoveVerdict(place_name(game, s), place_name(game, t), game.action_name(s, slot), visits, refused, _causes_words(causes)))
    verdicts.sort(key=lambda v: (-v.refused / max(v.visits, 1), v.source, v.target))
    return verdicts


def _loop_words(names: Sequence[str], noun: str = "cells") -> str:
    """``stays in A``, ``alternates between A and B``, ``goes round A -> B -> C -> A``."""
    if len(set(names)) == 1:
        return f"stays in {names[0]}"
    if len(names) == 2:
        return f"alternates between {names[0]} and {names[1]}"
    if len(names) <= 8:
        return f"goes round {' -> '.join([*names, names[0]])} (every {len(names)} steps)"
    return f"goes round {len(set(names))} {noun}, every {len(names)} steps"


def _loop_explanation(game: Any, states: Sequence[Any], loop: Loop, tester: str) -> Explanation:
    names = [place_name(game, s) for s in loop.states]
    # the round as the reader follows it: from its first cell in reading order
    first = min(range(len(names)), key=lambda i: (names[i], i)) if len(set(names)) == len(names) else 0
    names = names[first:] + names[:first]
    moves = _moves_toward_goal(game, states, loop, tester)
    what = f"from {STEPS} on, {_loop_words(names, 'cells' if game.is_grid else 'states')} until the step budget ran out"
    listed = [m.text() for m in moves[:LISTED_MOVES]]
    if len(moves) > LISTED_MOVES:
        listed.append(f"{len(moves) - LISTED_MOVES} more moves toward the goal")
    if not moves:
        listed.append("no move out of the loop leads nearer the goal past the walls")
    template = "; ".join([what, *listed])
    cells = tuple(dict.fromkeys(names))
    return Explanation("loop", _with_steps(template, f"step {loop.start}"), template, loop.start, loop, cells, tuple(moves))


def _wander_explanation(game: Any, states: Sequence[Any]) -> Explanation:
    dist = goal_distances(game)
    ds = [int(dist[_automaton_state(game, r), r.system]) for r in states]
    near = min(range(len(ds)), key=lambda i: (ds[i] if ds[i] >= 0 else 1 << 30, i))
    cells = {place_name(game, r.system) for r in states}
    template = "never settled into a loop before the step budget ran out"
    where = "cells" if game.is_grid else "states"
    text = (
        f"{template}: went through {len(cells)} {where} and ended in {place_name(game, states[-1].system)}, "
        f"{_moves(ds[-1])} from meeting the system objective past the walls (nearest: {_moves(ds[near])}, "
        f"at step {near} in {place_name(game, states[near].system)})"
    )
    return Explanation("wander", text, template, extra={"nearest": ds[near], "nearest_step": near, "end": ds[-1]})


def _moves(n: int) -> str:
    return "1 move" if n == 1 else f"{n} moves"


def explain(trace: Any, game: Any = None) -> Explanation:
    """A failing run (an :class:`~experiments.evaluation.episodes.Trace`) in one line; see
    the module docstring. ``game`` defaults to the one the trace was played on; a trace
    without states (not recorded) is explained by its reason."""
    from .violations import violation_of

    reason = str(trace.reason or trace.verdict.get("system_objective", ""))
    if trace.planner_error:
        return Explanation("planner", reason, reason)
    game = game if game is not None else getattr(trace, "game", None)
    if trace.kind != "sut" or game is None or not trace.states:
        return Explanation("reason", reason, reason)
    outcome = trace.verdict.get("system_objective")
    if outcome == "violated":
        v = violation_of(game.artifact, [r.system for r in trace.states])
        if v is None:
            return Explanation("reason", reason, reason)
        template = f"{reason}: {v.text(STEPS)}"
        return Explanation("violation", _with_steps(template, f"step {v.step}"), template, v.step, extra={"violation": v.to_dict()})
    if outcome != "open":
        return Explanation("reason", reason, reason)
    loop = find_loop([r.system for r in trace.states], [(r.system, r.history, r.agent) for r in trace.states])
    if loop is None:
        return _wander_explanation(game, trace.states)
    return _loop_explanation(game, trace.states, loop, trace.tester)


# --------------------------------------------------------------------------- folding


@dataclass(frozen=True)
class Outcome:
    """Runs that ended the same way: their seeds (and tests, where the runs of one report
    row played several, as a benchmark's split), their kind of failure (``sut``, ``test``,
    ``trap``) and the line that says what happened (the steps ranged over the runs)."""

    kind: str
    what: str
    text: str
    seeds: tuple[int, ...]
    tests: tuple[str, ...] = ()
    """Each run's test (``env_id``), beside ``seeds``."""
    steps: tuple[int, ...] = ()
    """The step each run's failure began at (the loop's first step, the violation's step)."""
    first: Explanation | None = None
    """The first run's explanation."""

    def runs_words(self) -> str:
        """``seed 3``, ``seeds 0-9 (10 runs)``; runs of several tests: ``3 runs (a, b, c)``."""
        if len(set(self.tests)) > 1:
            from pathlib import Path

            names = list(dict.fromkeys(Path(t).stem for t in self.tests))
            shown = ", ".join(names[:4]) + (f" and {len(names) - 4} more" if len(names) > 4 else "")
            return f"{len(self.seeds)} runs ({shown})"
        return seed_words(self.seeds)

    def line(self) -> str:
        """``seeds 0-9 (10 runs): from step 2 on, alternates between ...``."""
        return f"{self.runs_words()}: {self.text}"

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "what": self.what,
            "text": self.text,
            "seeds": list(self.seeds),
            "runs": len(self.seeds),
            "steps": list(self.steps),
            "line": self.line(),
            "explanation": None if self.first is None else self.first.to_dict(),
        }


def seed_words(seeds: Sequence[int]) -> str:
    """``seed 3``, ``seeds 0-9 (10 runs)``, ``seeds 0-3, 7, 9 (6 runs)``: runs of consecutive
    seeds written as ranges."""
    ordered = sorted(set(seeds))
    if len(ordered) == 1:
        return f"seed {ordered[0]}"
    parts: list[str] = []
    begin = prev = ordered[0]
    for s in [*ordered[1:], None]:
        if s is not None and s == prev + 1:
            prev = s
            continue
        parts.append(str(begin) if begin == prev else f"{begin}{'-' if prev > begin + 1 else ', '}{prev}")
        if s is not None:
            begin = prev = s
    return f"seeds {', '.join(parts)} ({len(ordered)} runs)"


def steps_words(steps: Sequence[int]) -> str:
    """``step 2``, or ``steps 2-18`` for several runs' steps."""
    lo, hi = min(steps), max(steps)
    return f"step {lo}" if lo == hi else f"steps {lo}-{hi}"


def fold(runs: Sequence[tuple[int, str, Explanation]], tests: Sequence[str] = ()) -> list[Outcome]:
    """Gather ``(seed, kind, explanation)`` of failing runs (of the tests ``tests``, one per
    run, when a row's runs played several) into one :class:`Outcome` per way of failing (the
    same kind and template), most runs first (then first seen). A line of one run is that
    run's own; of several, their template with the steps they began at (``from steps 2-18 on``)."""
    groups: dict[tuple[str, str], list[int]] = {}
    for i, (_, kind, e) in enumerate(runs):
        groups.setdefault((kind, e.template), []).append(i)
    out = []
    for (kind, template), members in groups.items():
        first = runs[members[0]][2]
        steps = [s for s in (runs[i][2].step for i in members) if s is not None]
        if len(members) == 1:
            text = first.text
        else:
            text = _with_steps(template, steps_words(steps)) if steps else template
        out.append(Outcome(kind, first.what, text, tuple(runs[i][0] for i in members), tuple(tests[i] for i in members) if tests else (), tuple(steps), first))
    order = {id(o): i for i, o in enumerate(out)}
    return sorted(out, key=lambda o: (-len(o.seeds), order[id(o)]))
