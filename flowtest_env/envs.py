"""Single-agent Gymnasium environments: the system under test (SUT) is the learner.

The environment side is the synthesized test: its restrictions (walls, reactive
doors) and, in agent problems, its test agent moving by the synthesized strategy.
Everything is played by the shared :class:`~flowtest_env.game.TestGame`; this module
adds spaces, rewards, observations, rendering and registration data.

:class:`FlowTestEnv` is the base; one thin subclass per built-in problem carries the
problem's documentation (``FlowTest-<Name>-v0``), and :class:`RandomGridEnv` draws
each episode from a pool of seeded random grid problems.
"""

from __future__ import annotations

import importlib.util
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from synthesis.artifacts.artifact import TestArtifact
from synthesis.problems.random_grid import FAMILIES
from synthesis.problems.random_worlds import POOL_KINDS, WORLDS

from .compiled import OUTCOMES
from .config import EnvConfig, config_from, with_option_signature
from .draws import draw_test
from .encoding import Encoder, ObservationLayout, make_encoder
from .game import GRID_ACTIONS, MET, VIOLATED, GameError, RunState, TestGame
from .memory import PlaceMemory
from .pools import random_grid_arguments, random_grid_tests
from .render import Renderer, ansi, make_renderer
from .sources import TestLike, game_for
from .validation import action_index, one_of, positive_int
from .wrappers import DistancePotential, shared_position_slice

DEFAULT_MAX_STEPS: dict[str, int] = {
    "example1": 50,
    "small-reactive": 50,
    "beaver-rescue": 50,
    "motion-primitives": 100,
    "refueling": 100,
    "mars-exploration": 200,
    "maze1": 100,
    "maze2": 100,
    "patrolling": 200,
}


def default_max_steps(game: TestGame) -> int:
    """The step budget of a test: the built-in's (:data:`DEFAULT_MAX_STEPS`), else four
    steps per place of the system, at least 50 (room for detours the test forces)."""
    name = game.artifact.name
    if name in DEFAULT_MAX_STEPS:
        return DEFAULT_MAX_STEPS[name]
    return max(50, 4 * len(game.ts.places))


RENDER_EXTRA = 'pip install "flowtest[render]"'
"""How to install what ``render_mode="human"`` needs (pygame, through the ``render`` extra)."""


def render_modes(pygame_found: bool | None = None) -> list[str]:
    """The single env's render modes: ``rgb_array`` and ``ansi``. ``"human"`` is drawn by
    Gymnasium's ``HumanRendering`` over ``rgb_array`` when pygame is installed; without
    pygame the env lists ``"human"`` itself, so ``gymnasium.make`` hands it to the env,
    which says what to install (instead of Gymnasium's advice to install its own extra)."""
    found = importlib.util.find_spec("pygame") is not None if pygame_found is None else pygame_found
    return ["rgb_array", "ansi"] if found else ["rgb_array", "ansi", "human"]


def check_human_rendering() -> None:
    """Raise unless pygame, which ``render_mode="human"`` draws with, can be imported.

    Raises
    ------
    gymnasium.error.DependencyNotInstalled
        Naming the extra to install.
    """
    try:
        import pygame  # noqa: F401
    except ImportError as e:
        raise gym.error.DependencyNotInstalled(
            f"render_mode='human' opens a window with pygame, which is not installed: {RENDER_EXTRA} (or pip install pygame-ce)"
        ) from e


@with_option_signature()
class FlowTestEnv(gym.Env[np.ndarray, np.int64]):
    """## Description

    A synthesized FlowTest test as an environment: the learner is the system under
    test (SUT), the environment enforces the test's restrictions and moves its test
    agent. An episode is one test run: it ends when the system objective is met or
    violated, or when the step budget runs out. The test objective stays hidden; the
    verdict at the end of the episode tells whether the test realized it.

    ## Action Space

    ``Discrete(5)`` on grids: ``0`` N, ``1`` S, ``2`` E, ``3`` W, ``4`` stay.
    On graphs ``Discrete(k + 1)``: action ``i < k`` takes the ``i``-th outgoing edge of
    the current state (``k`` the largest out-degree), action ``k`` stays.
    Actions that do not exist from the current state, or are restricted now, are
    *masked*: ``info["action_mask"]`` (``int8``, every step and reset),
    :meth:`action_masks` (``bool``, for sb3-contrib's MaskablePPO), or the
    :class:`~flowtest_env.wrappers.ActionMaskObservation` wrapper. A masked action
    leaves the SUT in place. The mask is all zeros once the episode has ended.

    ## Observation Space

    ``obs_kind="flat"`` (default): a ``float32`` vector in ``[0, 1]``;
    ``obs_kind="padded"`` (grid problems up to ``pad_to x pad_to``, default 8): one
    flat shape for every grid test, so a policy trained on one test plays others;
    ``obs_kind="grid"`` (grid problems): an image-like ``uint8[C, H, W]`` encoding
    (free cells, static walls and shown restrictions per direction, test agent,
    system, goal, the system objective's own cells, refuel cells, fuel, objective
    progress). See :mod:`flowtest_env.encoding`. Never the hidden test objective.

    ## Rewards

    ``-step_cost`` (0.01) per step; ``-restricted_penalty`` (0.05) more for a masked
    action; ``+goal_reward`` (1) when the system objective is met;
    ``-violation_penalty`` (1) when it is violated.

    ## Starting State

    The problem's initial state and history; the test agent at its start (after its
    first move when it moves first).

    ## Termination

    Terminated when the system objective is met (its automaton accepts) or violated
    (no run can meet it any more: a rejecting sink such as fuel 0, or a terminal state
    that does not accept). Truncated after ``max_steps`` steps. ``info["verdict"]`` at
    the end: ``system_objective`` (``"met"``/``"violated"``/``"open"``),
    ``test_objective_realized``, ``restrictions`` (decisions taken with at least one
    restricted move out of the SUT's state), ``blocked_attempts`` (masked actions
    taken) and ``steps``. ``info["system_state"]`` every step: ``[row, col]``,
    ``[[row, col], fuel]`` or a state name.

    ## Arguments

    ``test``: a built-in name (``"maze2"``), a problem file (synthesized once, then
    cached), an artifact file (``flowtest synthesize --out``), or a ``Problem``,
    ``SynthesizedTest`` or ``TestArtifact`` object (:func:`flowtest_env.sources.load_test`;
    ``problem`` is an older name for it). ``setting`` (``"instantaneous"``/``"accumulative"``:
    which restrictions are shown), ``max_steps``, ``obs_kind``, ``render_mode``
    (``"rgb_array"``, ``"ansi"``; ``"human"`` through Gymnasium's HumanRendering),
    ``view`` (``"system"`` or ``"engineer"``: the picture also shows the hidden test
    cells), ``tile_size`` and the reward weights.
    ``memory``: ``"none"`` (default), ``"visited"`` (the places the SUT has occupied
    this episode) or ``"counts"`` (how often, capped: :mod:`flowtest_env.memory`), appended
    to a flat observation (as the
    :class:`~flowtest_env.wrappers.VisitedPlaces` wrapper; a reactive test answers the
    run's history, which the observation alone does not show). ``shaping``: 0 (off,
    default) or the scale of potential-based shaping towards the SUT's own objective, with
    discount ``shaping_gamma`` (as :class:`~flowtest_env.wrappers.DistanceShaping`).
    ``numeric_infos``: ``True`` for numbers-only infos (the state index, the outcome code
    0/1/2), which libraries that turn infos into tensors (TorchRL) need. All options are
    one :class:`~flowtest_env.config.EnvConfig` (``env.config``), given as keyword
    arguments or as ``config=EnvConfig(...)``.

    ## Registered Configurations

    ``FlowTest-v0`` (any test: pass ``test=``), ``FlowTest-<Name>-v0`` for every
    built-in problem (see the subclasses) and ``FlowTest-RandomGrid-v0``;
    ``flowtest_env.ENV_IDS`` lists the ones with a fixed test.
    """

    metadata: dict[str, Any] = {"render_modes": render_modes(), "render_fps": 4}

    def __init__(self, test: TestLike = "maze2", *, problem: TestLike | None = None, config: EnvConfig | None = None, **options: Any) -> None:
        if problem is not None:  # the older name of `test`
            test = problem
        config = config_from(type(self).__name__, config, options)
        game = game_for(test, config.setting)
        self._configure([game], config.with_max_steps(default_max_steps(game)))
        self.problem = game.artifact.name

    # ------------------------------------------------------------------ set-up

    def _configure(self, games: list[TestGame], config: EnvConfig) -> None:
        """Set the env up for ``games`` (a pool of one or more) under ``config`` (its
        ``max_steps`` given)."""
        if config.render_mode == "human":
            check_human_rendering()
            raise ValueError(
                "render_mode='human' is drawn by gymnasium.make(..., render_mode='human') (Gymnasium's HumanRendering); "
                "building the env class directly, pass render_mode='rgb_array' and wrap it in gymnasium.wrappers.HumanRendering"
            )
        one_of("render_mode", config.render_mode, (None, *self.metadata["render_modes"]))
        assert config.max_steps is not None
        self.config = config
        obs_kind, pad_to, memory = config.obs_kind, config.pad_to, config.memory
        self.games = games
        self.encoders: list[Encoder] = [make_encoder(g, obs_kind, pad_to) for g in games]
        first = self.encoders[0].space
        for g, e in zip(games, self.encoders, strict=True):
            if e.space != first or g.n_actions != games[0].n_actions:
                raise GameError(f"problem {g.artifact.name!r} does not share the pool's observation or action space")
        self.memory: PlaceMemory | None = None
        if memory != "none":
            self.memory = PlaceMemory(shared_position_slice(self.encoders), memory)
            first = spaces.Box(0.0, 1.0, shape=(int(first.shape[0]) + self.memory.size,), dtype=np.float32)
        self._potential = DistancePotential(config.shaping) if config.shaping > 0 else None
        self._phi = 0.0
        self.observation_space = first
        self.action_space = spaces.Discrete(games[0].n_actions)
        self.render_mode = config.render_mode  # Gymnasium reads it off the env
        self._index = 0
        self.game = games[0]
        self.encoder = self.encoders[0]
        self._renderers: dict[int, Renderer] = {}
        self.run: RunState | None = None
        self._draw_key: int | None = None  # the seed of the test draws (flowtest_env.draws)
        self._episode = -1  # episodes since that seed

    # ------------------------------------------------------------------ API

    @property
    def max_steps(self) -> int:
        """The step budget of an episode (``config.max_steps``: by default the test's own,
        :func:`default_max_steps`)."""
        assert self.config.max_steps is not None
        return self.config.max_steps

    @property
    def obs_kind(self) -> str:
        """The observation's encoding (``config.obs_kind``)."""
        return self.config.obs_kind

    @property
    def artifact(self) -> TestArtifact:
        """The synthesized test of the current episode."""
        return self.game.artifact

    def _choose_game(self) -> int:
        """Which game of the pool the next episode plays (the base env has one)."""
        return 0

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Start a test run. ``seed`` seeds ``self.np_random`` and keys the pool's test
        draws (:mod:`flowtest_env.draws`: a reset without a seed plays the key's next
        episode). ``info`` carries ``system_state`` and ``action_mask``."""
        super().reset(seed=seed)
        if seed is not None:
            self._draw_key, self._episode = int(seed), 0
        else:
            self._episode += 1
        self._index = self._choose_game()
        self.game = self.games[self._index]
        self.encoder = self.encoders[self._index]
        self.run = self.game.reset()
        if self.memory is not None:
            self.memory.reset()
        if self._potential is not None:
            self._phi = self._potential(self.game, self.run)
        return self._observe(self.run), self._info(self.run)

    def _observe(self, run: RunState) -> np.ndarray:
        """The encoder's observation, with the SUT's memory when asked for."""
        obs = self.encoder.encode(run)
        return obs if self.memory is None else self.memory(obs)

    def step(self, action: Any) -> tuple[np.ndarray, SupportsFloat, bool, bool, dict[str, Any]]:
        """The SUT takes ``action``; the test answers (restrictions, test agent).

        Raises
        ------
        gymnasium.error.ResetNeeded
            Before ``reset()`` or after the episode ended.
        gymnasium.error.InvalidAction
            If ``action`` is not an integer of the action space: a float, a bool, a
            string or an array of another shape (a masked action is *not* an error).
        """
        run = self.run
        if run is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        if run.done or run.steps >= self.max_steps:
            raise gym.error.ResetNeeded("the episode has ended; call reset()")
        a = action_index(action, self.game.n_actions)
        out = self.game.step(run, a)
        reward = -self.config.step_cost
        if out.restricted or out.invalid:
            reward -= self.config.restricted_penalty
        terminated = run.done
        if run.outcome == MET:
            reward += self.config.goal_reward
        elif run.outcome == VIOLATED:
            reward -= self.config.violation_penalty
        if self._potential is not None:
            phi = 0.0 if terminated else self._potential(self.game, run)
            reward += self.config.shaping_gamma * phi - self._phi
            self._phi = phi
        truncated = not terminated and run.steps >= self.max_steps
        info = self._info(run)
        if terminated or truncated:
            info["verdict"] = self._verdict(run)
        return self._observe(run), float(reward), terminated, truncated, info

    def _info(self, run: RunState) -> dict[str, Any]:
        state = np.int64(run.system) if self.config.numeric_infos else self.game.state_json(run.system)
        return {"system_state": state, "action_mask": self.game.action_mask(run)}

    def _verdict(self, run: RunState) -> dict[str, Any]:
        v = self.game.verdict(run)
        if self.config.numeric_infos:
            v["system_objective"] = OUTCOMES.index(v["system_objective"])
        return v

    def observation_layout(self) -> ObservationLayout:
        """Which entries of the observation are which (the current test's; see
        :func:`flowtest_env.observation_layout`)."""
        lay = self.encoder.layout()
        return lay if self.memory is None else lay.with_memory(self.memory.size, self.memory.kind)

    def action_masks(self) -> np.ndarray:
        """``bool[n_actions]``: the legal actions now (sb3-contrib's MaskablePPO convention)."""
        if self.run is None:
            raise gym.error.ResetNeeded("call reset() before action_masks()")
        return self.game.action_mask(self.run).astype(bool)

    def verdict(self) -> dict[str, Any]:
        """The running verdict of the current episode."""
        if self.run is None:
            raise gym.error.ResetNeeded("call reset() before verdict()")
        return self.game.verdict(self.run)

    def action_meanings(self) -> list[str]:
        """Names of the actions from the current state (``N``.. or ``-> <state>``, ``stay``)."""
        s = self.run.system if self.run is not None else int(self.game.ts.initial)
        return [self.game.action_name(s, a) for a in range(self.game.n_actions)]

    def render(self) -> np.ndarray | str | None:
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array' or 'ansi' to make()")
            return None
        run = self.run if self.run is not None else self.game.reset()
        if self.render_mode == "ansi":
            return ansi(self.game, run, self.config.view)
        return self.frame(run)

    def frame(self, run: RunState | None = None) -> np.ndarray:
        """The ``rgb_array`` picture of ``run`` (default: the current run)."""
        run = run if run is not None else (self.run if self.run is not None else self.game.reset())
        r = self._renderers.get(self._index)
        if r is None:
            r = self._renderers[self._index] = make_renderer(self.game, self.config.tile_size, self.config.view)
        return r.frame(run)

    def close(self) -> None:
        self._renderers.clear()
        super().close()

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_renderers"] = {}  # rebuilt on demand
        return state


# ---------------------------------------------------------------- the built-ins


class Example1Env(FlowTestEnv):
    """## Description

    The paper's running example (``example1``): a 3x5 grid, start at the bottom
    centre, goals in the two top corners, test cells ``I`` at (0,2), (2,0), (2,4).
    Static walls (both directions) make every path to a goal pass an ``I`` cell.

    ## Action Space

    ``Discrete(5)``: N, S, E, W, stay.

    ## Observation Space

    Flat ``float32[186]`` (default) or ``obs_kind="grid"``: ``uint8[14, 3, 5]``.

    ## Rewards

    -0.01 per step, -0.05 more for a masked action, +1 at a goal.

    ## Termination

    At a goal (met). Truncated after 50 steps.

    ## Registered Configurations

    * ``FlowTest-Example1-v0``
    """

    def __init__(self, test: TestLike = "example1", **kwargs: Any) -> None:
        super().__init__(test, **kwargs)


class SmallReactiveEnv(FlowTestEnv):
    """## Description

    The paper's second running example (``small-reactive``): a 2x3 grid, start (1,0),
    goal (0,2), test cells I1 (0,0) and I2 (1,2). Reactive doors open and close with the
    history so that every run to the goal visits both I1 and I2.

    ## Action Space

    ``Discrete(5)``: N, S, E, W, stay.

    ## Observation Space

    Flat ``float32[78]`` (default) or ``obs_kind="grid"``: ``uint8[14, 2, 3]``.

    ## Rewards

    -0.01 per step, -0.05 more for a masked action, +1 at the goal.

    ## Termination

    At the goal (met). Truncated after 50 steps.

    ## Registered Configurations

    * ``FlowTest-SmallReactive-v0`` (``setting="instantaneous"``; pass
      ``setting="accumulative"`` to keep doors met under a history shown)
    """

    def __init__(self, test: TestLike = "small-reactive", **kwargs: Any) -> None:
        super().__init__(test, **kwargs)


class BeaverRescueEnv(FlowTestEnv):
    """## Description

    ``beaver-rescue``, a graph: a rescue robot leaves the lab through door 1 or door 2,
    fetches the beaver and comes back through a door to the goal. Reactive restrictions
    make it use both doors.

    ## Action Space

    ``Discrete(3)``: take the first or the second outgoing edge of the current state,
    or stay (see :meth:`FlowTestEnv.action_meanings`).

    ## Observation Space

    Flat ``float32[45]`` only (a graph has no image-like encoding).

    ## Rewards

    -0.01 per step, -0.05 more for a masked action, +1 at the goal with the beaver.

    ## Termination

    At the goal (met if the beaver was fetched, violated otherwise). Truncated after
    50 steps.

    ## Registered Configurations

    * ``FlowTest-BeaverRescue-v0``
    """

    def __init__(self, test: TestLike = "beaver-rescue", **kwargs: Any) -> None:
        super().__init__(test, **kwargs)


class MotionPrimitivesEnv(FlowTestEnv):
    """## Description

    ``motion-primitives``, a graph of 15 states: a legged robot shows motion
    primitives (jump, stand, lie) at three platforms; doors to the goal open according
    to the primitives already shown, so it must show all three kinds.

    ## Action Space

    ``Discrete(4)``: one action per outgoing-edge slot (three: the largest out-degree),
    and stay.

    ## Observation Space

    Flat ``float32[77]`` only (a graph has no image-like encoding).

    ## Rewards

    -0.01 per step, -0.05 more for a masked action, +1 at the goal.

    ## Termination

    At the goal (met). Truncated after 100 steps.

    ## Registered Configurations

    * ``FlowTest-MotionPrimitives-v0``
    """

    def __init__(self, test: TestLike = "motion-primitives", **kwargs: Any) -> None:
        super().__init__(test, **kwargs)


class RefuelingEnv(FlowTestEnv):
    """## Description

    ``refueling``: a 5x5 grid with fuel (max 10, a move costs 1, the refuel cell (0,4)
    refills). Reach the goal (0,0) from (4,0) without running dry. Static walls force a
    detour that leaves the system with fuel 1 in the ``L`` region far from the goal.

    ## Action Space

    ``Discrete(5)``: N, S, E, W, stay (only stay at fuel 0).

    ## Observation Space

    Flat ``float32[358]`` (default) or ``obs_kind="grid"``: ``uint8[18, 5, 5]``, with
    ``unsafe``, ``refuel`` and ``fuel`` planes.

    ## Rewards

    -0.01 per step, -0.05 more for a masked action, +1 at the goal, -1 when fuel runs
    out.

    ## Termination

    At the goal (met) or at fuel 0 (violated). Truncated after 100 steps.

    ## Registered Configurations

    * ``FlowTest-Refueling-v0``
    """

    def __init__(self, test: TestLike = "refueling", **kwargs: Any) -> None:
        super().__init__(test, **kwargs)


class MarsExplorationEnv(FlowTestEnv):
    """## Description

    ``mars-exploration``: a 6x6 grid with fuel, two refuel stations, ice (1,4) and rock
    (4,1) samples to drop off at (3,0) or (4,5), and the goal (0,0). Static walls make
    the rover sample both and run low on fuel (the shipped test is a time-limited answer:
    flow 2, its cut count not proven minimal).

    ## Action Space

    ``Discrete(5)``: N, S, E, W, stay.

    ## Observation Space

    Flat ``float32[622]`` (default) or ``obs_kind="grid"``: ``uint8[23, 6, 6]``, with
    ``dropoff``, ``ice``, ``rock``, ``unsafe``, ``refuel``, ``fuel`` and
    objective-progress planes.

    ## Rewards

    -0.01 per step, -0.05 more for a masked action, +1 when the objective is met, -1
    when it is violated (fuel 0, the goal with a sample not dropped off, or fuel too low
    for the way left round the walls).

    ## Termination

    Met or violated as above. Truncated after 200 steps.

    ## Registered Configurations

    * ``FlowTest-MarsExploration-v0``
    """

    def __init__(self, test: TestLike = "mars-exploration", **kwargs: Any) -> None:
        super().__init__(test, **kwargs)


class Maze1Env(FlowTestEnv):
    """## Description

    ``maze1``: a 7x5 maze; a test agent climbs the middle column (it moves up or
    waits, and leaves through a park above the top). It blocks the system's shortcuts so
    that the system visits I1, I2 and I3 before the goal (0,0). The system moves first.

    ## Action Space

    ``Discrete(5)``: N, S, E, W, stay; a move into the test agent's cell is masked.

    ## Observation Space

    Flat ``float32[426]`` (default) or ``obs_kind="grid"``: ``uint8[14, 7, 5]``, with a
    ``test_agent`` plane.

    ## Rewards

    -0.01 per step, -0.05 more for a masked action, +1 at the goal.

    ## Termination

    At the goal (met). Truncated after 100 steps.

    ## Registered Configurations

    * ``FlowTest-Maze1-v0``
    """

    def __init__(self, test: TestLike = "maze1", **kwargs: Any) -> None:
        super().__init__(test, **kwargs)


class Maze2Env(FlowTestEnv):
    """## Description

    ``maze2``, the headline environment: a 5x5 maze with four blocked cells; the test
    agent lives on the central plus, starts at the centre and moves first. It realizes
    the synthesized reactive restrictions by standing in the system's way, so every
    run from (4,0) to the goal (0,4) visits I1 (3,4) and I2 (1,0).

    ## Action Space

    ``Discrete(5)``: N, S, E, W, stay; a move into the test agent's cell is masked.

    ## Observation Space

    Flat ``float32[306]`` (default) or ``obs_kind="grid"``: ``uint8[14, 5, 5]``.

    ## Rewards

    -0.01 per step, -0.05 more for a masked action, +1 at the goal.

    ## Termination

    At the goal (met). Truncated after 100 steps.

    ## Registered Configurations

    * ``FlowTest-Maze2-v0``
    """

    def __init__(self, test: TestLike = "maze2", **kwargs: Any) -> None:
        super().__init__(test, **kwargs)


class PatrollingEnv(FlowTestEnv):
    """## Description

    ``patrolling``: a 6x6 grid with fuel; a test agent patrols column 2 (up, down or
    wait) and pushes the fuel-limited system, going from (5,5) to the goal (5,0), to
    run low on fuel far from the goal. Refuel at (1,5).

    ## Action Space

    ``Discrete(5)``: N, S, E, W, stay; a move into the test agent's cell is masked.

    ## Observation Space

    Flat ``float32[512]`` (default) or ``obs_kind="grid"``: ``uint8[18, 6, 6]``, with
    ``test_agent``, ``refuel`` and ``fuel`` planes.

    ## Rewards

    -0.01 per step, -0.05 more for a masked action, +1 at the goal, -1 when the fuel
    runs out.

    ## Termination

    At the goal (met) or at fuel 0 (violated). Truncated after 200 steps.

    ## Registered Configurations

    * ``FlowTest-Patrolling-v0``
    """

    def __init__(self, test: TestLike = "patrolling", **kwargs: Any) -> None:
        super().__init__(test, **kwargs)


def random_grid_pool(
    size: Any,
    family: Any,
    n: Any,
    seeds: Any,
    kind: Any,
    pool: str | None,
    split: str,
    count: int,
    world: Any,
) -> tuple[int, str, int, tuple[int, ...], str, str]:
    """The checked ``(size, family, n, seeds, kind, world)`` of a random-grid pool: the
    explicit arguments, or the named ``pool``'s ``split`` (shared by the single and the
    vector env, so both refuse the same arguments with the same message).

    Raises
    ------
    ValueError
        On a size, ``n`` or seed that is not an integer (``2.5``, ``True``, ``"01"``), an
        unknown family, kind or world, or an empty seed pool.
    """
    if isinstance(seeds, (str, bytes)) or not hasattr(seeds, "__iter__"):
        raise ValueError(f"seeds must be a list of non-negative integers, not {seeds!r}")
    seeds = tuple(seeds)
    for s in seeds:
        if isinstance(s, (bool, np.bool_)) or not isinstance(s, (int, np.integer)) or s < 0:
            raise ValueError(f"seeds must be non-negative integers, not {s!r}")
    if pool is None:
        size = positive_int("size", size)
        n = None if n is None else positive_int("n", n)
    else:
        count = positive_int("count", count)
        # n=1 passes: specs of earlier versions listed it next to a pool
        defaults: dict[str, tuple[Any, ...]] = {
            "size": (5,),
            "family": ("reachability",),
            "n": (None, 1),
            "seeds": (tuple(range(8)),),
            "kind": ("reactive",),
            "world": ("empty",),
        }
        given = {"size": size, "family": family, "n": n, "seeds": seeds, "kind": kind, "world": world}
        clash = [k for k, v in given.items() if v not in defaults[k]]
        if clash:
            raise ValueError(
                f"pool={pool!r} decides the size, family, n, seeds, kind and world; it cannot be combined with "
                f"{', '.join(f'{k}={given[k]!r}' for k in clash)} (pass split= and count= to choose its seeds)"
            )
    size, family, n, seeds, kind, world = random_grid_arguments(pool, split, count, size, family, n, seeds, kind, world)
    one_of("family", family, tuple(FAMILIES))
    one_of("kind", kind, POOL_KINDS)
    one_of("world", world, WORLDS)
    if not seeds:
        raise ValueError("the seed pool is empty")
    return positive_int("size", size), family, positive_int("n", n), seeds, kind, world


@with_option_signature()
class RandomGridEnv(FlowTestEnv):
    """## Description

    Random grid worlds of the paper's scalability study: an empty ``size x size`` grid
    with a start, a goal and one cell per proposition, drawn by seed. Each reset draws
    one problem of a pool of seeded instances (episode ``e`` after ``reset(seed=k)`` plays
    :func:`flowtest_env.draws.draw_test` ``(k, e, len(pool))``, as the vector envs do); the pool is
    synthesized with deterministic budgets (:func:`flowtest_env.random_grid.pool_options`)
    once per FlowTest and solver version and cached in memory and on disk
    (``$FLOWTEST_CACHE_DIR``, default ``~/.cache/flowtest``, under a key of the versions and
    options).

    ## Action Space

    ``Discrete(5)``: N, S, E, W, stay.

    ## Observation Space

    Flat (default) or ``obs_kind="grid"``; the layout (goal, system propositions) is
    part of the observation because it changes between episodes. The registered
    configuration (5x5, reachability): flat ``float32[306]``, grid ``uint8[14, 5, 5]``.

    ## Rewards

    -0.01 per step, -0.05 more for a masked action, +1 when the system objective is
    met, -1 when it is violated.

    ## Termination

    Met or violated; truncated after ``max_steps`` (default ``4 * size * size``).

    ## Arguments

    ``size`` (5), ``family`` (``"reachability"``, ``"reaction"``, ``"safety"``),
    ``n`` (spec size; 1 for reachability, 2 otherwise by default), ``seeds`` (the pool,
    default ``0..7``), ``kind`` (``"reactive"``: reactive doors, ``"static"``: walls, or
    ``"agent"``: a test agent), ``world`` (``"empty"``, ``"blocked"``: blocked cells,
    ``"fuel"``: a fuel grid; :mod:`synthesis.problems.random_worlds`), and the base arguments. Or
    ``pool`` (a named pool, e.g. ``"reaction2/7x7"`` or ``"reachability1/5x5/fuel/agent"``,
    see :mod:`flowtest_env.pools`) with ``split`` (``"train"``, ``"validation"``,
    ``"test"``: seed ranges that never overlap) and ``count`` (its first seeds, default
    8): the pool then decides size, family, n, world, kind and seeds.

    ## Registered Configurations

    * ``FlowTest-RandomGrid-v0``: 5x5, reachability with one test cell, reactive,
      seeds 0..7.
    """

    def __init__(
        self,
        size: int = 5,
        family: str = "reachability",
        n: int | None = None,
        seeds: list[int] | tuple[int, ...] = tuple(range(8)),
        kind: str = "reactive",
        *,
        pool: str | None = None,
        split: str = "train",
        count: int = 8,
        world: str = "empty",
        config: EnvConfig | None = None,
        **options: Any,
    ) -> None:
        config = config_from(type(self).__name__, config, options)
        size, family, n, seeds, kind, world = random_grid_pool(size, family, n, seeds, kind, pool, split, count, world)
        tests = random_grid_tests(pool, split, count, size, family, n, seeds, kind, world)
        games = [TestGame(a, config.setting) for a in tests]
        self._configure(games, config.with_max_steps(4 * size * size))
        self.problem = f"random-{size}x{size}-{family}{n}" + ("" if world == "empty" else f"-{world}")

    def _choose_game(self) -> int:
        """The test of this episode, by :func:`flowtest_env.draws.draw_test` of the seed
        given at the last seeded ``reset`` and the episodes since (never seeded: a key
        drawn once from ``self.np_random``)."""
        if self._draw_key is None:
            self._draw_key, self._episode = int(self.np_random.integers(2**63)), 0
        return draw_test(self._draw_key, self._episode, len(self.games))


BUILTIN_ENVS: dict[str, tuple[str, type[FlowTestEnv]]] = {
    "example1": ("Example1", Example1Env),
    "small-reactive": ("SmallReactive", SmallReactiveEnv),
    "beaver-rescue": ("BeaverRescue", BeaverRescueEnv),
    "motion-primitives": ("MotionPrimitives", MotionPrimitivesEnv),
    "refueling": ("Refueling", RefuelingEnv),
    "mars-exploration": ("MarsExploration", MarsExplorationEnv),
    "maze1": ("Maze1", Maze1Env),
    "maze2": ("Maze2", Maze2Env),
    "patrolling": ("Patrolling", PatrollingEnv),
}
"""Built-in problem name -> (ID stem, env class)."""

__all__ = ["FlowTestEnv", "RandomGridEnv", "BUILTIN_ENVS", "GRID_ACTIONS"] + [c.__name__ for _, c in BUILTIN_ENVS.values()]
