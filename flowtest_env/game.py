"""The test game: the rules of one synthesized test run, shared by every FlowTest environment.

A :class:`TestGame` is built once from a :class:`~synthesis.artifacts.artifact.TestArtifact` and
holds only look-up tables; a :class:`RunState` is the small mutable state of one run.
Every rule below is a table or dictionary look-up, so nothing is solved at step time
(design.md: "a step is a few array or dictionary look-ups").

Rules (docs/method.md §6-7)
----------------------
* **Moves.** The system under test (SUT) picks an *action*: on grids ``N, S, E, W,
  stay`` (actions 0-4); on graphs one action per outgoing edge *slot* of its current
  state (slot ``k`` = its ``k``-th outgoing move, in the artifact's move order) and a
  last action ``stay``. An action without a move from the current state is *invalid*.
* **Restrictions.** Obstacle problems (``static``/``reactive``/``mixed``): a move is
  restricted while the history is ``h`` iff ``artifact.strategy.blocked[h, move]``
  (static walls included). Agent problems: static walls, and every move into the place
  the test agent occupies (the agent realizes the reactive restrictions ``R(q)`` by
  standing there, docs/method.md §7). Stay is always allowed on non-terminal states.
* **Attempts.** An invalid or restricted action leaves the SUT in place (as a stay)
  and is counted in ``blocked_attempts``; the legal-action mask never offers one.
* **The test agent** answers every SUT step from its synthesized table
  (:class:`synthesis.test_agent.controller.AgentController`); when it moves first it also answers once
  at reset.
* **Termination.** The run ends when the system objective is *met* (the history's
  ``q_sys`` accepts) or *violated*: no run from the SUT's state and history that
  respects the enforced restrictions can reach acceptance any more (a rejecting sink
  such as fuel 0 or an unsafe state, a terminal state that does not accept, or fuel
  too low for the way round the walls). This "doomed" table is computed once, by
  backward reachability over ``T x B_pi``. With an external tester (the PettingZoo env) only
  the static walls count, since the tester's choices are not known in advance.
* **Verdict.** ``system_objective`` (``"met"``/``"violated"``/``"open"``),
  ``test_objective_realized`` (the history's ``q_test`` accepts), ``restrictions``
  (number of SUT decisions taken while at least one move out of its state was
  restricted: a static wall, a reactive restriction or the test agent in the way),
  ``blocked_attempts`` (actions refused: restricted or invalid) and ``steps``.
"""

from __future__ import annotations

from collections.abc import Hashable
from dataclasses import dataclass, field
from functools import cached_property, lru_cache
from typing import Any

import numpy as np

from synthesis.artifacts.artifact import TestArtifact
from synthesis.test_agent.controller import AgentController

GRID_ACTIONS: tuple[str, ...] = ("N", "S", "E", "W")
"""Action names of grid problems, in action order; action 4 is ``stay``."""

OPEN, MET, VIOLATED = "open", "met", "violated"


class GameError(ValueError):
    """An artifact or a call the test game cannot honour (bad action index, bad agent move)."""


def printable(text: str) -> str:
    """``text`` with every non-printable character escaped (``"\\x1b"``), so a name never
    reaches a terminal or a log raw. Artifacts refuse such names; a Problem built in
    Python may still hold one.

    >>> printable("a\x1b[2Jb")
    'a\\x1b[2Jb'
    """
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)


def grid_cell(place: Hashable) -> tuple[int, int]:
    """The ``(row, col)`` of a place of a grid system (its places are cells)."""
    if not (isinstance(place, tuple) and len(place) == 2):
        raise GameError(f"place {place!r} is not a grid cell (row, col)")
    row, col = place
    return int(row), int(col)


def fuel_level(state: Hashable) -> int:
    """The fuel of a state of a fuel grid (its states are ``((row, col), fuel)``)."""
    if not (isinstance(state, tuple) and len(state) == 2):
        raise GameError(f"state {state!r} is not a fuel-grid state ((row, col), fuel)")
    return int(state[1])


@dataclass
class RunState:
    """The state of one test run.

    Attributes
    ----------
    system
        The SUT's state (index into ``artifact.system.states``).
    history
        The state of ``B_pi`` after reading the labels seen so far.
    agent, memory
        The test agent's state and strategy memory (``-1`` without a test agent).
    visited
        States met since the current history began (the accumulative setting shows
        their restrictions).
    steps
        SUT steps taken.
    restrictions, blocked_attempts
        See the module docstring (the verdict).
    outcome
        ``"open"``, ``"met"`` or ``"violated"``.
    override
        Restrictions of the SUT's current state chosen by another tester for this step
        (a slot bitmask on top of the static walls), or ``None``: the synthesized ones.
        Cleared by every SUT step.
    """

    system: int
    history: int
    agent: int = -1
    memory: int = -1
    visited: set[int] = field(default_factory=set)
    steps: int = 0
    restrictions: int = 0
    blocked_attempts: int = 0
    outcome: str = OPEN
    override: int | None = None

    def copy(self) -> RunState:
        """An independent copy (for search over runs)."""
        return RunState(
            self.system,
            self.history,
            self.agent,
            self.memory,
            set(self.visited),
            self.steps,
            self.restrictions,
            self.blocked_attempts,
            self.outcome,
            self.override,
        )

    def key(self) -> tuple[int, int, int, int]:
        """What decides the future of the run: ``(system, history, agent, memory)``."""
        return (self.system, self.history, self.agent, self.memory)

    @property
    def done(self) -> bool:
        """Whether the run has ended (the system objective is met or violated)."""
        return self.outcome != OPEN


@dataclass(frozen=True)
class StepOutcome:
    """What a SUT step did: whether it moved, and whether it was refused and why."""

    moved: bool
    restricted: bool
    invalid: bool


def _coreachable_to_acceptance(artifact: TestArtifact, enforced: np.ndarray, nxt: np.ndarray) -> np.ndarray:
    """``bool[n_hist, n_states]``: from ``(s, h)`` some run of T that respects the
    enforced restrictions (``enforced[h, move]``) reaches a history whose system part
    accepts (backward reachability, vectorised over the edges of ``T x B_pi``; ``nxt[h, s]``:
    the history after entering ``s``)."""
    ts = artifact.system
    dba = artifact.histories
    nh, n = dba.n_states, ts.n_states
    hm, mm = np.nonzero(~enforced)
    st = np.flatnonzero(ts.stay)
    h = np.arange(nh)
    src = np.concatenate([hm * n + ts.src[mm], (h[:, None] * n + st[None, :]).ravel()])
    dst = np.concatenate([nxt[hm, ts.dst[mm]] * n + ts.dst[mm], (nxt[:, st] * n + st[None, :]).ravel()])
    can = np.repeat(dba.accepting[:, 0], n)
    while True:  # backward fixpoint: one round per step of the longest shortest path
        grow = src[can[dst] & ~can[src]]
        if grow.size == 0:
            return can.reshape(nh, n)
        can[grow] = True


def _permanent_walls(artifact: TestArtifact) -> np.ndarray:
    """``bool[n_moves]``: static obstacles that hold between their two places at every
    state the system can reach.

    A move's *place move* is its pair ``(place[src], place[dst])``; on fuel grids one
    place move stands for a move at every fuel level. Tied walls (refueling, patrolling)
    are static at every reachable fuel level and so permanent; per-level cuts
    (``tie_places="none"``) are not, and showing them at every level would draw walls
    that are not there. Reachability is over the moves that are not static obstacles,
    from the initial state.
    """
    ts = artifact.system
    static = artifact.strategy.static_obstacles
    if not static.any():  # no static obstacle, no wall (most reactive tests)
        return np.zeros(ts.n_moves, dtype=bool)
    src, dst = ts.src[~static], ts.dst[~static]
    reach = np.zeros(ts.n_states, dtype=bool)
    reach[int(ts.initial)] = True
    frontier = reach.copy()
    while frontier.any():  # breadth-first, one layer per round
        nxt = np.zeros_like(reach)
        nxt[dst[frontier[src]]] = True
        frontier = nxt & ~reach
        reach |= frontier
    n_places = len(ts.places)
    key = ts.place[ts.src].astype(np.int64) * n_places + ts.place[ts.dst]
    open_keys = np.unique(key[reach[ts.src] & ~static])  # sparse: no n_places^2 table
    permanent: np.ndarray = static & ~np.isin(key, open_keys)
    return permanent


@lru_cache(maxsize=16)
def _masks_of_bits(n_actions: int) -> np.ndarray:
    """``int8[2**n_actions, n_actions]``: the mask of every action bitmask (read-only,
    shared by the games with this many actions)."""
    table = ((np.arange(1 << n_actions)[:, None] >> np.arange(n_actions)[None, :]) & 1).astype(np.int8)
    table.flags.writeable = False
    return table


def _slot_moves(src: np.ndarray, action: list[str], n_states: int, n_slots: int | None) -> np.ndarray:
    """``int64[n_states, n_slots]``: the move of each action slot of each state, -1 if none.

    Grids (``n_slots`` given): slot ``k`` of a state is its move of action
    ``GRID_ACTIONS[k]`` (a later move of the same state and action wins). Graphs
    (``n_slots=None``): slot ``k`` is the state's ``k``-th outgoing move in move order,
    and there are as many slots as the most moves out of one state (at least one).

    Raises
    ------
    GameError
        On a grid move whose action is not one of :data:`GRID_ACTIONS`.
    """
    src = np.asarray(src, dtype=np.int64)
    n_moves = int(src.size)
    moves = np.arange(n_moves, dtype=np.int64)
    if n_slots is not None:
        index = {a: k for k, a in enumerate(GRID_ACTIONS)}
        try:
            col = np.fromiter((index[a] for a in action), dtype=np.int64, count=n_moves)
        except KeyError as exc:
            raise GameError(f"grid move with action {exc.args[0]!r}; expected one of {', '.join(GRID_ACTIONS)}") from None
        out = np.full((n_states, n_slots), -1, dtype=np.int64)
        out[src, col] = moves  # in move order: the last of duplicates wins, as assignment in a loop
        return out
    counts = np.bincount(src, minlength=n_states)
    width = max(1, int(counts.max()) if n_moves else 1)
    order = np.argsort(src, kind="stable")  # by state, move order kept within a state
    first = np.concatenate([[0], np.cumsum(counts)[:-1]])
    rank = np.arange(n_moves, dtype=np.int64) - first[src[order]]
    out = np.full((n_states, width), -1, dtype=np.int64)
    out[src[order], rank] = order
    return out


class TestGame:
    """The rules of a synthesized test, as look-up tables built once from its artifact.

    Parameters
    ----------
    artifact
        The synthesized test.
    setting
        ``"instantaneous"`` or ``"accumulative"``: which restrictions are *shown*
        (never which are enforced); default the artifact's.
    external_tester
        The reactive restrictions (or agent moves) come from another tester: a run is
        violated only when the static walls alone leave no way to meet the objective.

    Raises
    ------
    GameError
        On an unknown setting or an agent artifact without a controller.
    """

    __test__ = False

    def __init__(self, artifact: TestArtifact, setting: str | None = None, external_tester: bool = False) -> None:
        self.artifact = artifact
        ts = self.ts = artifact.system
        setting = setting or artifact.strategy.setting
        if setting not in ("instantaneous", "accumulative"):
            raise GameError(f"unknown obstacle setting {setting!r}; expected 'instantaneous' or 'accumulative'")
        self.setting = setting
        self.is_grid = ts.kind in ("grid", "fuel") and ts.layout is not None
        self.cells: list[tuple[int, int]] = [grid_cell(p) for p in ts.places] if self.is_grid else []
        """``cells[p]``: the ``(row, col)`` of place ``p`` (grids; empty on graphs)."""
        self.fuel: list[int] = [fuel_level(k) for k in ts.states] if ts.kind == "fuel" else [0] * ts.n_states
        """``fuel[s]``: the fuel of state ``s`` (fuel grids; 0 elsewhere)."""
        n = ts.n_states
        # ---- action slots
        slot_move = _slot_moves(ts.src, ts.action, n, len(GRID_ACTIONS) if self.is_grid else None)
        self.n_slots = int(slot_move.shape[1])
        self.n_actions = self.n_slots + 1
        self.stay_action = self.n_slots
        self.slot_move = slot_move
        """``int64[n_states, n_slots]``: the move of each action slot, -1 if none."""
        exists = self.slot_move >= 0
        self.successor = np.where(exists, ts.dst[np.maximum(self.slot_move, 0)], np.arange(n)[:, None]).astype(np.int64)
        """``int64[n_states, n_slots]``: the state an action slot leads to (itself if none)."""
        self.dst_place = np.where(exists, ts.place[self.successor], -2).astype(np.int64)
        # ---- restrictions per (history, state) as slot bitmasks
        strat = artifact.strategy
        self.agent_controller: AgentController | None = None
        if artifact.kind == "agent":
            if not artifact.agent or "controller" not in artifact.agent:
                raise GameError(f"agent artifact {artifact.name!r} has no test agent controller")
            self.agent_controller = AgentController.from_dict(artifact.agent["controller"])
            enforced = np.broadcast_to(strat.static_obstacles[None, :], strat.blocked.shape)
        else:
            enforced = strat.blocked
        self.enforced = np.ascontiguousarray(enforced)
        """``bool[n_hist, n_moves]``: restrictions the game enforces itself."""
        self.permanent_wall = _permanent_walls(artifact)
        """``bool[n_moves]``: static obstacles that are walls of the map, drawn and
        encoded at all times; the other static obstacles hold only at some states of
        their cell (a fuel grid with walls per fuel level) and are shown, like reactive
        restrictions, while the system is at such a state."""
        # slot bitmasks: bit k of a state's mask is slot k (column -1 of the padded
        # per-move tables is False, so a slot without a move has no bit)
        weights = np.int64(1) << np.arange(self.n_slots, dtype=np.int64)
        pad = np.zeros((self.enforced.shape[0], self.enforced.shape[1] + 1), dtype=bool)
        pad[:, :-1] = self.enforced
        self.restricted_array: np.ndarray = pad[:, self.slot_move].astype(np.int64) @ weights
        """``int64[n_hist, n_states]``: :attr:`restricted_bits` as an array."""
        self.restricted_bits: list[list[int]] = self.restricted_array.tolist()
        stay_bit = np.int64(1) << self.stay_action
        self.exists_array: np.ndarray = exists.astype(np.int64) @ weights + np.where(ts.stay, stay_bit, np.int64(0))
        """``int64[n_states]``: :attr:`exists_bits` as an array."""
        self.exists_bits: list[int] = self.exists_array.tolist()
        per_move = np.zeros(ts.n_moves + 1, dtype=bool)
        per_move[:-1] = strat.static_obstacles
        self.static_bits: list[int] = (per_move[self.slot_move].astype(np.int64) @ weights).tolist()
        per_move[:-1] = ts.restrictable & ~strat.static_obstacles
        self.choosable_bits: list[int] = (per_move[self.slot_move].astype(np.int64) @ weights).tolist()
        """Slots a tester may restrict per state: existing, in the harness, not a static wall."""
        self._mask_table: np.ndarray | None = _masks_of_bits(self.n_actions) if self.n_actions <= 12 else None
        # ---- histories and objectives
        letter = ts.letter_of_state(artifact.letters)
        self.next_history_array: np.ndarray = artifact.histories.delta[:, letter]
        """``int[n_hist, n_states]``: :attr:`next_history` as an array."""
        comps = artifact.histories.components
        self.q_sys = comps[:, 0].astype(np.int64) if comps is not None else np.zeros(artifact.histories.n_states, np.int64)
        self.sys_accepting: list[bool] = artifact.histories.accepting[:, 0].tolist()
        self.test_accepting: list[bool] = artifact.histories.accepting[:, 1].tolist()
        self.external_tester = external_tester
        walls = np.broadcast_to(strat.static_obstacles[None, :], strat.blocked.shape)
        self.doomed_array: np.ndarray = ~_coreachable_to_acceptance(artifact, walls if external_tester else self.enforced, self.next_history_array)
        """``bool[n_hist, n_states]``: :attr:`doomed` as an array."""
        self.slot_list: list[list[int]] = self.slot_move.tolist()
        self.place_list: list[int] = ts.place.tolist()
        # ---- the test agent
        if self.agent_controller is not None:
            ctl = self.agent_controller
            self.agent_place: list[int] = [-1 if p is None else int(p) for p in ctl.agent_places]
            self.agent_first = ctl.first == "agent"
            moves = np.asarray((artifact.agent or {}).get("moves", []), dtype=np.int64).reshape(-1, 2)
            na = len(ctl.agent_places)
            self.agent_moves = np.zeros((na, na), dtype=bool)
            self.agent_moves[moves[:, 0], moves[:, 1]] = True
            """``bool[n_agent, n_agent]``: the moves of the agent's transition system."""
        else:
            self.agent_place = []
            self.agent_first = False
            self.agent_moves = np.zeros((0, 0), dtype=bool)

    # the tables of a step as nested lists (faster to index one entry at a time than
    # arrays), built on first use: the vector env compiles from the arrays instead

    @cached_property
    def next_history(self) -> list[list[int]]:
        """``next_history[h][s]``: the history after entering ``s``."""
        out: list[list[int]] = self.next_history_array.tolist()
        return out

    @cached_property
    def doomed(self) -> list[list[bool]]:
        """``doomed[h][s]``: no run from ``s`` with history ``h`` that respects the enforced
        restrictions can meet the system objective any more."""
        out: list[list[bool]] = self.doomed_array.tolist()
        return out

    @cached_property
    def succ_list(self) -> list[list[int]]:
        """``succ_list[s][slot]``: :attr:`successor` as nested lists."""
        out: list[list[int]] = self.successor.tolist()
        return out

    @cached_property
    def into_bits(self) -> list[dict[int, int]]:
        """``into_bits[s]``: the slots of state ``s`` leading into each place (a slot
        bitmask per place), for the test agent's blocks; built on first use."""
        out: list[dict[int, int]] = []
        for row in self.dst_place.tolist():
            d: dict[int, int] = {}
            for k, p in enumerate(row):
                if p >= 0:
                    d[p] = d.get(p, 0) | (1 << k)
            out.append(d)
        return out

    # ------------------------------------------------------------------ queries

    @property
    def has_agent(self) -> bool:
        """Whether the test has a test agent (agent problems)."""
        return self.agent_controller is not None

    @property
    def n_agent_states(self) -> int:
        """Number of the test agent's states (cells, then parks); 0 without an agent."""
        return len(self.agent_place)

    def action_name(self, state: int, action: int) -> str:
        """A readable name of ``action`` in ``state`` (``"N"``, ``"stay"``, ``"-> d1"``)."""
        if action == self.stay_action:
            return "stay"
        if self.is_grid:
            return GRID_ACTIONS[action]
        m = self.slot_list[state][action]
        return "(none)" if m < 0 else f"-> {printable(str(self.ts.states[int(self.ts.dst[m])]))}"

    def agent_bits(self, run: RunState) -> int:
        """Slots of the SUT's state blocked by the test agent's position."""
        if run.agent < 0:
            return 0
        p = self.agent_place[run.agent]
        return self.into_bits[run.system].get(p, 0) if p >= 0 else 0

    def restricted_bits_of(self, run: RunState) -> int:
        """Slots of the SUT's state restricted now (walls, reactive restrictions or the
        tester's override, agent)."""
        if run.override is not None:
            return run.override | self.static_bits[run.system] | self.agent_bits(run)
        return self.restricted_bits[run.history][run.system] | self.agent_bits(run)

    def legal_bits(self, run: RunState, restricted: int | None = None) -> int:
        """Legal actions as a bitmask; ``restricted`` overrides the synthesized restrictions
        (slot bitmask chosen by a tester). Never empty on a live run: without stay and
        with every move refused, ``stay`` is offered as a no-op."""
        r = self.restricted_bits_of(run) if restricted is None else restricted | self.agent_bits(run)
        bits = self.exists_bits[run.system] & ~r
        return bits if bits else 1 << self.stay_action

    def mask_of_bits(self, bits: int) -> np.ndarray:
        """``int8[n_actions]`` mask of a bitmask (a fresh array)."""
        if self._mask_table is not None:
            row: np.ndarray = self._mask_table[bits].copy()
            return row
        return np.array([(bits >> a) & 1 for a in range(self.n_actions)], dtype=np.int8)

    def action_mask(self, run: RunState) -> np.ndarray:
        """``int8[n_actions]``: the actions the SUT may take now (all zeros once the run ended)."""
        if run.done:
            return np.zeros(self.n_actions, dtype=np.int8)
        return self.mask_of_bits(self.legal_bits(run))

    def shown_moves(self, run: RunState) -> list[int]:
        """The moves shown as obstacles now (enforced restrictions out of the displayed
        states: the current one, or every state visited under the current history in the
        accumulative setting). Test-agent blocks are not included: the agent is shown.
        With a tester's override, the restrictions it chose on the current state."""
        if run.override is not None:
            s, bits = run.system, run.override | self.static_bits[run.system]
            return [self.slot_list[s][k] for k in range(self.n_slots) if (bits >> k) & 1 and self.slot_list[s][k] >= 0]
        h = run.history
        states = (run.system,) if self.setting == "instantaneous" else run.visited | {run.system}
        out: list[int] = []
        rb = self.restricted_bits[h]
        for s in states:
            bits = rb[s]
            k = 0
            while bits:
                if bits & 1:
                    out.append(self.slot_list[s][k])
                bits >>= 1
                k += 1
        return out

    def verdict(self, run: RunState) -> dict[str, Any]:
        """The running verdict (see the module docstring)."""
        return {
            "system_objective": run.outcome,
            "test_objective_realized": bool(self.test_accepting[run.history]),
            "restrictions": run.restrictions,
            "blocked_attempts": run.blocked_attempts,
            "steps": run.steps,
        }

    # ------------------------------------------------------------------ dynamics

    def reset(self, agent_first_move: bool = True) -> RunState:
        """A fresh run: the SUT at ``s0`` with the initial history; the agent at its start
        (and, if it moves first and ``agent_first_move``, after its synthesized first move)."""
        s0 = int(self.ts.initial)
        h0 = self.artifact.initial_history()
        run = RunState(system=s0, history=h0, visited={s0})
        if self.agent_controller is not None:
            run.agent, run.memory = self.agent_controller.reset()
            if self.agent_first and agent_first_move:
                self.agent_respond(run)
        self._settle(run)
        return run

    def synthesized_agent_move(self, run: RunState) -> tuple[int, int]:
        """The synthesized test agent's answer ``(agent_state, memory)`` to the run now."""
        if self.agent_controller is None:
            raise GameError(f"test {self.artifact.name!r} has no test agent")
        return self.agent_controller.respond(run.agent, run.memory, run.system, run.history)

    def agent_respond(self, run: RunState) -> None:
        """Move the test agent by its synthesized strategy."""
        run.agent, run.memory = self.synthesized_agent_move(run)

    def agent_legal(self, run: RunState) -> np.ndarray:
        """``bool[n_agent]``: the agent's legal moves now (along its transition system,
        never into the SUT's place)."""
        ok: np.ndarray = self.agent_moves[run.agent].copy()
        sp = self.place_list[run.system]
        for a in np.flatnonzero(ok):
            if self.agent_place[a] == sp:
                ok[a] = False
        if not ok.any():
            ok[run.agent] = True
        return ok

    def agent_move(self, run: RunState, agent_state: int) -> None:
        """Move the test agent to ``agent_state`` chosen by another tester (memory kept).

        Raises
        ------
        GameError
            If the move is not legal now.
        """
        if not (0 <= agent_state < self.n_agent_states) or not self.agent_legal(run)[agent_state]:
            raise GameError(f"illegal test agent move {run.agent} -> {agent_state}")
        run.agent = int(agent_state)

    def system_step(self, run: RunState, action: int, restricted: int | None = None) -> StepOutcome:
        """Apply the SUT's ``action`` (history, visited set, counters, outcome).

        ``restricted`` overrides the synthesized restrictions with a slot bitmask chosen
        by another tester (the PettingZoo env); the agent's block always applies.

        Raises
        ------
        GameError
            If ``action`` is not an action index, or the run already ended.
        """
        if run.done:
            raise GameError("the run has ended; reset it")
        if not (0 <= action < self.n_actions):
            raise GameError(f"action {action} is outside 0..{self.n_actions - 1}")
        s, h = run.system, run.history
        r = self.restricted_bits_of(run) if restricted is None else restricted | self.agent_bits(run)
        if r & self.exists_bits[s]:
            run.restrictions += 1
        bit = 1 << action
        legal = self.exists_bits[s] & ~r
        invalid = not (self.exists_bits[s] & bit) and not (legal == 0 and action == self.stay_action)
        refused = bool(r & bit) and not invalid
        nxt = s if (action == self.stay_action or invalid or refused) else self.succ_list[s][action]
        if invalid or refused:
            run.blocked_attempts += 1
        run.steps += 1
        run.override = None
        h2 = self.next_history[h][nxt]
        run.system = nxt
        if h2 != h:
            run.history = h2
            run.visited = {nxt}
        else:
            run.visited.add(nxt)
        self._settle(run)
        return StepOutcome(moved=nxt != s, restricted=refused, invalid=invalid)

    def _settle(self, run: RunState) -> None:
        h, s = run.history, run.system
        if self.sys_accepting[h]:
            run.outcome = MET
        elif self.doomed[h][s]:
            run.outcome = VIOLATED

    def step(self, run: RunState, action: int) -> StepOutcome:
        """One round of the single-agent game: the SUT acts, then (if the run goes on) the
        synthesized test agent answers."""
        out = self.system_step(run, action)
        if self.has_agent and not run.done:
            self.agent_respond(run)
        return out

    def state_json(self, state: int) -> object:
        """A system state written as in problem-format.md (a name with a non-printable
        character escaped, see :func:`printable`)."""
        out = self.ts.to_json_state(state)
        return printable(out) if isinstance(out, str) else out
