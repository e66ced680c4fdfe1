"""A synthesized test as a runtime: step it from your own harness, no Gymnasium loop.

Your system runs where it runs (a robot, a simulator, a ROS node); after each of its moves
you tell the test where the system is, and the test answers what it restricts now, where
its test agent moves and the verdict so far. The rules are
:class:`~flowtest_env.game.TestGame`'s, which every FlowTest environment plays;
``flowtest serve`` offers the same over JSON lines (docs/runtime.md)::

    from flowtest_env.runtime import TestRuntime

    rt = TestRuntime.load("small-reactive")   # a built-in name, an artifact or problem file
    status = rt.reset()
    status = rt.step(state=[1, 1])             # the system entered (1, 1)
    status["restricted"]                       # moves out of it refused now, and by what
    status["verdict"], status["reason"]        # system_objective, ...; why the run ended

A **status** (:meth:`TestRuntime.status`) is a plain ``dict`` of JSON values: ``state``,
``step``, ``history`` and ``history_name``, ``restricted`` (``[{"action", "to", "by"}]``,
``by`` one of ``wall``, ``door``, ``agent``), ``allowed``, ``to``, ``mask``, ``agent``
(``null`` or ``{"state", "name", "place"}``), ``verdict``, ``reason``, ``done`` and
``max_steps``. It is the harness's view: the history and the verdict tell how far the
hidden test objective got, so a system under test must never be shown them (docs/runtime.md
lists what it may see: :func:`describe` and the ``step`` fields of the planner protocol).
"""

from __future__ import annotations

import json
from typing import Any

from synthesis.artifacts.artifact import TestArtifact

from .game import GRID_ACTIONS, MET, VIOLATED, GameError, RunState, TestGame


class RuntimeRefused(ValueError):
    """A step the test cannot take: a state the system cannot have entered (not one move
    away, or through a move the test restricts now), an unknown action, or a step after the
    run has ended. The run is unchanged. ``code`` names the case for a program
    (:data:`REFUSALS`)."""

    def __init__(self, message: str, code: str = "bad_request") -> None:
        super().__init__(message)
        self.code = code


REFUSALS = {
    "bad_request": "neither or both of state and action given, or an unknown field",
    "not_a_state": "the state is not a state of the test's system",
    "not_one_move": "the state is not one move from the system's state",
    "restricted": "the move is restricted now (a wall, a door or the test agent)",
    "cannot_stay": "the system cannot stay in its state now",
    "not_an_action": "the action is no action of the system's state",
    "run_ended": "the run has ended; reset it",
}
"""The codes of :class:`RuntimeRefused`, and what each means."""

CAUSES = ("wall", "door", "agent")
"""Why a move is restricted: a static ``wall`` (on the map for the whole test), a ``door``
the test closes now (it may open again) or the test ``agent`` standing there."""


def describe(game: TestGame, max_steps: int | None) -> dict[str, Any]:
    """The public description of a test, as the system under test may know it: what the
    built-in systems know, no less and no more. Its name, kind, the system objective, the
    transition system as the artifact holds it with the static walls apart (``walls``:
    ``[from, to]`` moves the test refuses for good, taken out of ``moves`` and its
    per-move lists), the system objective's ``automaton``, the grid's action names
    (``None`` on graphs), the step budget and whether a test agent moves.

    ``automaton``: ``initial``, ``accepting`` (per automaton state) and ``next``, where
    ``next[q][s]`` is the automaton's state after the system enters (or stays in) state
    ``s`` in automaton state ``q``: at step 0 in state ``s0`` it is
    ``next[initial][s0]``, and the system objective is met once it is accepting (the
    automaton the built-in planners plan on, :class:`~flowtest_env.system_product.SystemProduct`).

    What the environments never show the system is left out here too: the test objective,
    and in ``system`` every proposition the system objective does not name (``labels`` keep
    only the system objective's) and the names of the grid cells that carry one
    (``layout.tokens``); the automaton reads the system objective's propositions only."""
    from synthesis.model.specs import parse_formula, propositions

    art = game.artifact
    system = art.system.to_dict()
    wall = [bool(w) for w in art.strategy.static_obstacles]
    moves = system["moves"]
    system["walls"] = [m for m, w in zip(moves, wall, strict=True) if w]
    for key in ("moves", "action", "restrictable"):
        if isinstance(system.get(key), list) and len(system[key]) == len(wall):
            system[key] = [x for x, w in zip(system[key], wall, strict=True) if not w]
    visible = set(propositions(parse_formula(art.objectives.get("system", "true"))))
    labels = system["labels"]
    hidden_places = {int(art.system.place[s]) for s, lab in enumerate(labels) if set(lab) - visible}
    hidden_cells = [game.ts.places[p] for p in hidden_places]
    system["labels"] = [[p for p in lab if p in visible] for lab in labels]
    if system.get("layout"):
        system["layout"] = {**system["layout"], "tokens": [t for t in system["layout"]["tokens"] if (t[0], t[1]) not in hidden_cells]}
    dba = art.system_automaton
    letter = game.ts.letter_of_state(art.letters)
    return {
        "name": art.name,
        "kind": art.kind,
        "objective": art.objectives.get("system", ""),
        "system": system,
        "automaton": {"initial": int(dba.initial), "accepting": [bool(a) for a in dba.accepting[:, 0]], "next": dba.delta[:, letter].tolist()},
        "actions": [*GRID_ACTIONS, "stay"] if game.is_grid else None,
        "max_steps": max_steps,
        "agent": game.has_agent,
    }


def refused_by(game: TestGame, run: RunState, slot: int) -> str:
    """Why action ``slot`` out of the system's state is restricted now: ``wall``, ``door``
    or ``agent`` (:data:`CAUSES`)."""
    bit = 1 << slot
    if game.static_bits[run.system] & bit:
        return "wall"
    if game.agent_bits(run) & bit:
        return "agent"
    return "door"


def restricted_moves(game: TestGame, run: RunState) -> list[dict[str, Any]]:
    """The moves out of the system's state the test refuses now: ``action`` (its name),
    ``to`` (the state it leads to) and ``by`` (:func:`refused_by`), in action order."""
    s = run.system
    bits = game.restricted_bits_of(run) & game.exists_bits[s]
    return [
        {"action": game.action_name(s, k), "to": game.state_json(game.succ_list[s][k]), "by": refused_by(game, run, k)}
        for k in range(game.n_slots)
        if bits >> k & 1
    ]


def state_of(game: TestGame, state: Any) -> int:
    """The index of a system state written as in problem-format.md (``[row, col]``,
    ``[[row, col], fuel]`` or a state name).

    Raises
    ------
    RuntimeRefused
        If it is not a state of the test's system.
    """
    ts = game.ts
    try:
        if ts.kind == "grid":
            if not (isinstance(state, (list, tuple)) and len(state) == 2):
                raise TypeError
            key: Any = (_int(state[0]), _int(state[1]))
        elif ts.kind == "fuel":
            if not (isinstance(state, (list, tuple)) and len(state) == 2 and isinstance(state[0], (list, tuple)) and len(state[0]) == 2):
                raise TypeError
            key = ((_int(state[0][0]), _int(state[0][1])), _int(state[1]))
        else:
            if not isinstance(state, str):
                raise TypeError
            key = state
        return ts.index(key)
    except (TypeError, KeyError):
        shape = {"grid": "[row, col]", "fuel": "[[row, col], fuel]"}.get(ts.kind, "a state name")
        raise RuntimeRefused(f"{_show(state)} is not a state of {game.artifact.name!r} (expected {shape})", "not_a_state") from None


def _int(x: Any) -> int:
    if isinstance(x, bool) or not isinstance(x, int):
        raise TypeError
    return x


def _show(x: Any) -> str:
    """``x`` as JSON (as the client wrote it), cut to 80 characters."""
    try:
        text = json.dumps(x)
    except (TypeError, ValueError):
        text = repr(x)
    return text if len(text) <= 80 else text[:80] + "..."


class TestRuntime:
    """One run of a synthesized test at a time, stepped by the system's states or actions.

    Parameters
    ----------
    artifact
        The test (:meth:`load` takes a name or a file).
    max_steps
        The step budget; default the environment's (:func:`flowtest_env.envs.default_max_steps`).
        The run is ``done`` once it is spent, as an environment truncates it.
    reveal
        Name the histories by what the test saw (``"saw I1; saw goal"``, which gives the
        hidden test objective away) instead of neutrally (``"q3"``, the default).

    Examples
    --------
    Your system moves; the runtime says what the test allows and blocks (here it closes the
    way east at ``[0, 1]`` until the system has visited ``I2``):

    >>> from flowtest_env.runtime import TestRuntime
    >>> rt = TestRuntime.load("small-reactive")      # a built-in, an artifact or a problem file
    >>> status = rt.reset()
    >>> status["state"], status["allowed"], status["to"]
    ([1, 0], ['N', 'E', 'stay'], [[0, 0], [1, 1], [1, 0]])
    >>> status = rt.step(state=[0, 0])               # or rt.step(action="N")
    >>> status = rt.step(state=[0, 1])
    >>> status["restricted"], status["allowed"]
    ([{'action': 'E', 'to': [0, 2], 'by': 'door'}], ['S', 'W', 'stay'])
    >>> for state in ([1, 1], [1, 2], [0, 2]):
    ...     status = rt.step(state=state)
    >>> status["done"], status["verdict"]
    (True, {'system_objective': 'met', 'test_objective_realized': True, 'restrictions': 1, 'blocked_attempts': 0, 'steps': 5})
    >>> status["reason"]
    'met the system objective in 5 steps'
    """

    __test__ = False

    def __init__(self, artifact: TestArtifact, max_steps: int | None = None, reveal: bool = False) -> None:
        from .envs import default_max_steps

        self.game = TestGame(artifact)
        self.max_steps = default_max_steps(self.game) if max_steps is None else int(max_steps)
        if self.max_steps < 1:
            raise ValueError(f"max_steps must be at least 1, not {max_steps}")
        descr = artifact.extras.get("history_descriptions") if isinstance(artifact.extras, dict) else None
        names = list(artifact.histories.names)
        if not reveal:
            self.history_names = [f"q{h}" for h in range(len(names))]
        else:
            self.history_names = [str(x) for x in descr] if isinstance(descr, list) and len(descr) == len(names) else names
        self.run: RunState = self.game.reset()

    @classmethod
    def load(cls, test: Any, max_steps: int | None = None, reveal: bool = False) -> TestRuntime:
        """The runtime of ``test``: a built-in name, an artifact file, a problem file
        (synthesized once, then cached) or a test object (:func:`flowtest_env.sources.load_test`).

        Raises
        ------
        synthesis.model.errors.ProblemError
            If ``test`` names no test, or the file is not a valid artifact or problem.
        """
        from .sources import load_test

        return cls(load_test(test), max_steps, reveal)

    def describe(self) -> dict[str, Any]:
        """The test's public description (:func:`describe`)."""
        return describe(self.game, self.max_steps)

    # ------------------------------------------------------------------ the run

    def reset(self) -> dict[str, Any]:
        """Start a new run (the test agent takes its first move if it moves first); its status."""
        self.run = self.game.reset()
        return self.status()

    @property
    def done(self) -> bool:
        """Whether the run has ended: the system objective met or violated, or the budget spent."""
        return self.run.done or self.run.steps >= self.max_steps

    def step(self, state: Any = None, action: Any = None) -> dict[str, Any]:
        """The system's next step, given as the ``state`` it entered (``[row, col]``,
        ``[[row, col], fuel]`` or a name; its own state is a stay) or as an ``action``
        (an index or a name: ``"N"``, ``"stay"``, ``"-> d1"``). Returns the new status.

        A state must be one move away, through a move the test allows now (the system
        cannot have gone through a closed door); an action is played as the environment
        plays it (a refused one is a blocked attempt: the system stays).

        Raises
        ------
        RuntimeRefused
            If the step cannot be taken (the run is then unchanged).
        """
        if (state is None) == (action is None):
            raise RuntimeRefused("give the system's new state or its action (one of them)", "bad_request")
        if self.done:
            raise RuntimeRefused("the run has ended; reset it", "run_ended")
        a = self._action_to(state) if state is not None else self._action(action)
        try:
            self.game.step(self.run, a)
        except GameError as exc:  # pragma: no cover - _action_to and _action check first
            raise RuntimeRefused(str(exc)) from None
        return self.status()

    def _action(self, action: Any) -> int:
        g, s = self.game, self.run.system
        if isinstance(action, int) and not isinstance(action, bool):
            if 0 <= action < g.n_actions:
                return action
        elif isinstance(action, str):
            names = [g.action_name(s, a) for a in range(g.n_actions)]
            for text in (action, f"-> {action}"):
                if text in names:
                    return names.index(text)
        known = ", ".join(g.action_name(s, a) for a in range(g.n_actions))
        raise RuntimeRefused(f"{_show(action)} is not an action here (an index 0..{g.n_actions - 1} or one of: {known})", "not_an_action")

    def _action_to(self, state: Any) -> int:
        g, run = self.game, self.run
        s, t = run.system, state_of(g, state)
        legal = g.legal_bits(run)
        if t == s:
            if legal >> g.stay_action & 1:
                return g.stay_action
            raise RuntimeRefused(f"the system cannot stay in {_show(g.state_json(s))} now", "cannot_stay")
        slots = [k for k in range(g.n_slots) if g.slot_list[s][k] >= 0 and g.succ_list[s][k] == t]
        if not slots:
            raise RuntimeRefused(f"{_show(g.state_json(t))} is not one move from {_show(g.state_json(s))}", "not_one_move")
        for k in slots:
            if legal >> k & 1:
                return k
        by = refused_by(g, run, slots[0])
        who = {"wall": "a wall", "door": "the test", "agent": "the test agent"}[by]
        raise RuntimeRefused(f"the move {_show(g.state_json(s))} -> {_show(g.state_json(t))} is restricted now (by {who})", "restricted")

    # ------------------------------------------------------------------ what the test says

    def restricted(self) -> list[dict[str, Any]]:
        """The moves out of the system's state the test refuses now (:func:`restricted_moves`):
        the action, the state it leads to, and ``by``: ``wall`` (a static wall), ``door``
        (a restriction of this history, which may open again) or ``agent`` (the test agent
        stands there)."""
        return restricted_moves(self.game, self.run)

    def reason(self) -> str | None:
        """Why the run ended, in one line (``None`` while it goes on): the system objective
        met (and in how many steps), violated (where), or the step budget spent."""
        g, run = self.game, self.run
        if run.outcome == MET:
            unrealized = "" if g.verdict(run)["test_objective_realized"] else " (without realizing the test objective)"
            return f"met the system objective in {run.steps} steps{unrealized}"
        if run.outcome == VIOLATED:
            return f"violated the system objective at step {run.steps}, entering {_show(g.state_json(run.system))}"
        if self.done:
            return f"did not meet the system objective within the step budget of {self.max_steps} steps"
        return None

    def status(self) -> dict[str, Any]:
        """The run now (see the module docstring); nothing changes."""
        g, run = self.game, self.run
        s = run.system
        mask = g.action_mask(run) if not self.done else g.action_mask(run) * 0
        allowed = [int(a) for a in mask.nonzero()[0]]
        agent = None
        if g.has_agent and g.agent_controller is not None:
            place = g.agent_place[run.agent]
            p = g.ts.places[place] if place >= 0 else None
            agent = {"state": run.agent, "name": g.agent_controller.agent_names[run.agent], "place": list(p) if isinstance(p, tuple) else p}
        return {
            "state": g.state_json(s),
            "step": run.steps,
            "history": run.history,
            "history_name": self.history_names[run.history],
            "restricted": self.restricted(),
            "allowed": [g.action_name(s, a) for a in allowed],
            "to": [g.state_json(s if a == g.stay_action else g.succ_list[s][a]) for a in allowed],
            "mask": mask.tolist(),
            "agent": agent,
            "verdict": g.verdict(run),
            "reason": self.reason(),
            "done": self.done,
            "max_steps": self.max_steps,
        }
