"""The two-player FlowTest environment (PettingZoo): a tester against a system under test.

## Description

One test run as a turn-based game between ``tester_0`` and ``system_0``, played by the
shared :class:`~flowtest_env.game.TestGame`. The synthesized test strategy ships as the
default tester (:func:`synthesized_tester`), so any system policy can be plugged in;
or a learned tester can be trained against a fixed system (:mod:`agents.testers`,
``flowtest train-tester``), and checked for traps exhaustively (:mod:`flowtest_env.fairness`).

* **Obstacle problems** (static, reactive, mixed): each round the tester first chooses
  which outgoing moves of the system's current state to restrict for this step, then
  the system moves. Static walls are part of the map (always enforced, never chosen).
* **Agent problems** (maze1, maze2, patrolling): the tester moves the test agent along
  its transition system; the system may not enter the agent's cell. Who moves first is
  the problem's (maze2: the tester; maze1, patrolling: the system).

## Action Spaces

``system_0``: as the single-agent env (grids: N, S, E, W, stay; graphs: edge slots +
stay). ``tester_0``: obstacle problems ``Discrete(2**k)`` (bit ``i`` of the action
restricts the ``i``-th move slot; ``k`` = 4 on grids); agent problems
``Discrete(n_agent_states)`` (the agent state to move to, parks included).

Masks (``observation["action_mask"]``) enforce the system's assumptions: the tester
may only restrict moves that exist, are in the test harness and are not static walls,
and may never restrict every move of the state; the test agent moves along its
transition system and never into the system's cell; the system takes only
unrestricted moves. An action outside the mask is replaced by the no-op (the tester
restricts nothing, the agent stays, the system stays) and costs the actor
``restricted_penalty``.

## Observation Spaces

``Dict(observation=..., action_mask=int8[n])`` per agent. The system sees what the
single-agent env shows (``obs_kind`` ``"flat"`` or ``"grid"``), with the restrictions the
tester chose this step. The tester sees everything: one-hots of the system's state,
the history and the test agent's state (and of the synthesized agent's strategy memory,
where that strategy has more than one memory value), so the synthesized test is a
function of the tester's observation (:class:`SynthesizedTester`).

## Options for RL libraries

* ``obs_key``, ``mask_key``: the names of the two Dict entries (``"observation"`` and
  ``"action_mask"`` by default, PettingZoo's classic envs, TorchRL and Tianshou;
  RLlib's masking modules read ``obs_key="observations"``).
* ``info_kind="numeric"``: every agent's infos hold the same numeric keys at every
  reset and step (``system_state``: the state index; the running verdict as numbers:
  ``system_objective`` 0 open / 1 met / 2 violated, ``test_objective_realized`` 0/1,
  ``restrictions``, ``blocked_attempts``, ``steps``), which libraries that stack infos
  into tensors need (TorchRL's ``PettingZooWrapper``). ``"full"`` (default): the
  single-agent env's infos, ``verdict`` a dict with strings at the end.
* ``same_spaces=True``: both agents get one observation space (flat ``float32``, padded
  with zeros to the longer one) and one action space (``Discrete`` of the larger; the
  padding actions are never in the mask), as Tianshou's ``PettingZooEnv`` requires.

## Rewards

``system_0``: ``-step_cost`` per step, ``+goal_reward`` (1) when its objective is met,
``-violation_penalty`` (1) when violated (the options of the single-agent env).
``tester_0``: at the end of a run that met the system objective, +1 if the test
objective was realized, -1 if not.

## Termination

When the system objective is met or violated (both agents; with an external tester only
the static walls count when deciding that no way to meet it is left); truncated after
``max_cycles`` rounds (each agent acted ``max_cycles`` times). ``infos[agent]["verdict"]``
at the end, as in the single-agent env.

## Parallel version

:func:`parallel_env` plays one round per ``step``, applying the actions in turn order.
Both players choose from the round-start observations, so neither sees the other's
choice of the same round:

* obstacle problems: the system's observation shows the synthesized restrictions, and a
  move the tester restricts in the same round is refused (a stay). With the synthesized
  tester the two coincide and the parallel game equals the AEC game;
* agent problems: the system does not see where the agent goes this round (a move into
  its new cell is refused: a stay), and when the system moves first (maze1, patrolling)
  the tester answers the round-start position, not the system's move of the round.

With the synthesized tester no state of the parallel game traps the system, and every
met run realizes the test objective except where the test agent must step in front of
the system right after the system's move: patrolling (physical walls), whose agent must
block the way into (3, 2) and, one round late in the parallel game, lets the system slip
past (``tests/flowtest_env/test_multiagent.py`` explores every system behaviour and checks both). For
exact turn-by-turn play, for patrolling's guarantee, and for a learned tester, use the
AEC version.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces
from pettingzoo import AECEnv, ParallelEnv
from pettingzoo.utils import wrappers

from .config import MULTIAGENT_UNUSED, EnvConfig, config_from, refuse_unused, with_option_signature
from .encoding import make_encoder
from .envs import check_human_rendering, default_max_steps
from .game import MET, OPEN, VIOLATED, RunState, TestGame
from .render import Renderer, ansi, make_renderer
from .sources import TestLike, game_for
from .validation import action_index, one_of, positive_int

TESTER, SYSTEM = "tester_0", "system_0"
INFO_KINDS = ("full", "numeric")
"""``info_kind`` values: the single-agent env's infos, or numbers only (see the module docstring)."""
OUTCOME_CODES: dict[str, int] = {OPEN: 0, MET: 1, VIOLATED: 2}
"""``system_objective`` in numeric infos: 0 open, 1 met, 2 violated."""
MULTIAGENT_DEFAULTS: dict[str, Any] = {"view": "engineer"}
"""Where the two-player env's option defaults differ from :class:`~flowtest_env.config.EnvConfig`'s:
its pictures show the hidden test cells."""
NUMERIC_INFO_KEYS = ("system_state", "system_objective", "test_objective_realized", "restrictions", "blocked_attempts", "steps")
"""The keys of every agent's numeric infos, at every reset and step."""


def env(**kwargs: Any) -> AECEnv:
    """The wrapped AEC environment (order enforcing, bounds checked).

    Examples
    --------
    The tester (here the synthesized test) and the system take turns:

    >>> from flowtest_env.multiagent import env, synthesized_tester
    >>> e = env(test="small-reactive")
    >>> e.reset(seed=0)
    >>> tester = synthesized_tester(e)
    >>> turns = []
    >>> for agent in e.agent_iter(max_iter=4):
    ...     observation, reward, termination, truncation, info = e.last()
    ...     turns.append((agent, info["system_state"]))
    ...     e.step(tester() if agent == "tester_0" else int(observation["action_mask"].argmax()))
    >>> turns
    [('tester_0', [1, 0]), ('system_0', [1, 0]), ('tester_0', [0, 0]), ('system_0', [0, 0])]
    """
    e: AECEnv = raw_env(**kwargs)
    e = wrappers.AssertOutOfBoundsWrapper(e)
    e = wrappers.OrderEnforcingWrapper(e)
    return e


def parallel_env(**kwargs: Any) -> ParallelFlowTestEnv:
    """The parallel version: one ``step`` plays one round, the agents' actions applied in
    turn order (so the system's action is chosen before it sees this round's tester
    choice when the tester moves first).

    Examples
    --------
    >>> from flowtest_env.multiagent import parallel_env, synthesized_tester
    >>> env = parallel_env(test="small-reactive")
    >>> observations, infos = env.reset(seed=0)
    >>> env.agents, sorted(observations["system_0"])
    (['tester_0', 'system_0'], ['action_mask', 'observation'])
    >>> tester = synthesized_tester(env)
    >>> observations, rewards, terminations, truncations, infos = env.step({"tester_0": tester(), "system_0": 0})
    >>> rewards, infos["system_0"]["system_state"]
    ({'tester_0': 0.0, 'system_0': -0.01}, [0, 0])
    """
    return ParallelFlowTestEnv(**kwargs)


# pettingzoo ships no type information (AECEnv, ParallelEnv are Any to mypy)
@with_option_signature(exclude=MULTIAGENT_UNUSED, **MULTIAGENT_DEFAULTS)
class raw_env(AECEnv):  # type: ignore[misc]  # noqa: N801 - PettingZoo's module shape
    """The AEC tester-vs-system environment (see the module docstring).

    Parameters
    ----------
    test
        The test: a built-in name (``maze2``, ``small-reactive``, ...), a problem file,
        an artifact file, or a ``Problem``/``SynthesizedTest``/``TestArtifact``
        (:func:`flowtest_env.sources.load_test`); ``problem`` is an older name for it.
    max_cycles
        Rounds before truncation (PettingZoo's name of ``max_steps``; default: the
        single-agent env's ``max_steps``).
    config, options
        The env options, one :class:`~flowtest_env.config.EnvConfig` (``env.config``) as
        ``config=`` or its fields as keyword arguments, checked by the same validator as
        the single-agent and vector envs' (:func:`~flowtest_env.config.config_from`).
        Those that apply here: ``setting`` (which restrictions are shown), ``max_steps``,
        ``obs_kind`` and ``pad_to`` (the system's observation), ``render_mode``
        (``"rgb_array"``, ``"ansi"``, or ``"human"``: a pygame window, with the ``render`` extra), ``view`` (default ``"engineer"``: the picture
        shows the hidden test cells), ``tile_size``, and the system's rewards
        ``step_cost``, ``restricted_penalty`` (also the tester's, for a refused action),
        ``goal_reward`` and ``violation_penalty``. The learner's ``memory``, ``shaping``,
        ``shaping_gamma`` and ``numeric_infos`` do not apply
        (:data:`~flowtest_env.config.MULTIAGENT_UNUSED`; ``info_kind`` is this env's own):
        a value other than their default is refused with a ``ValueError``.
    obs_key, mask_key
        The names of the observation's two Dict entries (``"observation"``,
        ``"action_mask"``; RLlib's masking modules read ``"observations"``).
    info_kind
        ``"full"`` (the single-agent env's infos) or ``"numeric"`` (the same numeric keys
        at every step, :data:`NUMERIC_INFO_KEYS`; for TorchRL).
    same_spaces
        Give both agents one padded observation space and one action space (Tianshou).

    Example
    -------
    >>> from flowtest_env import multiagent
    >>> e = multiagent.raw_env(test="small-reactive", obs_key="observations", info_kind="numeric")
    >>> e.reset()
    >>> sorted(e.observe("system_0"))
    ['action_mask', 'observations']
    >>> e.infos["system_0"]["system_objective"]
    0
    """

    metadata: dict[str, Any] = {
        "render_modes": ["rgb_array", "ansi", "human"],
        "name": "flowtest_v0",
        "is_parallelizable": True,
        "render_fps": 4,
    }

    def __init__(
        self,
        test: TestLike = "maze2",
        *,
        max_cycles: int | None = None,
        problem: TestLike | None = None,
        obs_key: str = "observation",
        mask_key: str = "action_mask",
        info_kind: str = "full",
        same_spaces: bool = False,
        config: EnvConfig | None = None,
        **options: Any,
    ) -> None:
        super().__init__()
        # the options shared with the single-agent and vector envs, checked by their one validator
        config = config_from("raw_env", config, options, defaults=MULTIAGENT_DEFAULTS)
        refuse_unused("the two-player env", config, MULTIAGENT_UNUSED, "it applies to the single-agent and vector envs")
        one_of("render_mode", config.render_mode, (None, *self.metadata["render_modes"]))
        if config.render_mode == "human":
            check_human_rendering()  # pygame, through the render extra: said before anything is built
        if max_cycles is not None:  # PettingZoo's name of the step budget
            max_cycles = positive_int("max_cycles", max_cycles)
            if config.max_steps is not None and config.max_steps != max_cycles:
                raise ValueError(f"max_cycles={max_cycles!r} and max_steps={config.max_steps!r}: max_cycles is the two-player name of max_steps, give one")
            config = config.replace(max_steps=max_cycles)
        one_of("info_kind", info_kind, INFO_KINDS)
        for name, key in (("obs_key", obs_key), ("mask_key", mask_key)):
            if not isinstance(key, str) or not key:
                raise ValueError(f"{name} must be a non-empty string, not {key!r}")
        if obs_key == mask_key:
            raise ValueError(f"obs_key and mask_key must differ, both are {obs_key!r}")
        if not isinstance(same_spaces, bool):
            raise ValueError(f"same_spaces must be True or False, not {same_spaces!r}")
        self.obs_key, self.mask_key, self.info_kind, self.same_spaces = obs_key, mask_key, info_kind, same_spaces
        if problem is not None:  # the older name of `test`
            test = problem
        game = game_for(test, config.setting, external_tester=True)
        self.game: TestGame = game
        self.problem = game.artifact.name
        config = config.with_max_steps(default_max_steps(game))
        assert config.max_steps is not None
        self.config: EnvConfig = config  # every option, read where it is used
        self.render_mode = config.render_mode  # PettingZoo's attribute
        self.encoder = make_encoder(game, config.obs_kind, config.pad_to)
        system_first = game.has_agent and not game.agent_first
        self.possible_agents = [SYSTEM, TESTER] if system_first else [TESTER, SYSTEM]
        n_test = game.n_agent_states if game.has_agent else 1 << game.n_slots
        self._n_hist = int(game.artifact.histories.n_states)
        self._n_states = game.ts.n_states
        controller = game.agent_controller
        # the strategy's memory is shown only where it has more than one value (built-ins: one)
        self._n_memory = controller.n_memory if controller is not None and controller.n_memory > 1 else 0
        self._n_tester_obs = self._n_states + self._n_hist + game.n_agent_states + self._n_memory
        tester_obs = spaces.Box(0.0, 1.0, shape=(self._n_tester_obs,), dtype=np.float32)
        system_obs = self.encoder.space
        n_by_agent = {TESTER: n_test, SYSTEM: game.n_actions}
        obs_by_agent: dict[str, spaces.Box] = {TESTER: tester_obs, SYSTEM: system_obs}
        if same_spaces:
            size = max(int(np.prod(b.shape)) for b in obs_by_agent.values())
            high = max(float(np.max(b.high)) for b in obs_by_agent.values())
            shared = spaces.Box(0.0, high, shape=(size,), dtype=np.float32)
            self._padded_size = size
            obs_by_agent = {TESTER: shared, SYSTEM: shared}
            n_by_agent = {a: max(n_by_agent.values()) for a in n_by_agent}
        self._action_spaces: dict[str, spaces.Discrete] = {a: spaces.Discrete(n) for a, n in n_by_agent.items()}
        self._observation_spaces: dict[str, spaces.Dict] = {
            a: spaces.Dict({obs_key: obs_by_agent[a], mask_key: spaces.Box(0, 1, (n_by_agent[a],), dtype=np.int8)}) for a in (TESTER, SYSTEM)
        }
        if not game.has_agent:
            bits = np.arange(n_test)
            self._choice_bits = bits
        self._renderer: Renderer | None = None
        self._window: HumanWindow | None = None
        self.run: RunState = game.reset(agent_first_move=False)
        self.agents: list[str] = []

    # ------------------------------------------------------------------ spaces

    def observation_space(self, agent: str) -> spaces.Dict:
        """The (cached, built once) observation space of ``agent``."""
        return self._observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.Discrete:
        """The (cached, built once) action space of ``agent``."""
        return self._action_spaces[agent]

    # ------------------------------------------------------------------ masks

    def tester_mask(self) -> np.ndarray:
        """``int8[n_tester_actions]``: the tester's legal actions now."""
        g, run = self.game, self.run
        n = int(self._action_spaces[TESTER].n)
        if run.done:
            return np.zeros(n, dtype=np.int8)
        if g.has_agent:
            return g.agent_legal(run).astype(np.int8)
        s = run.system
        allowed = g.choosable_bits[s]
        open_moves = g.exists_bits[s] & ~(1 << g.stay_action) & ~g.static_bits[s] & ~g.agent_bits(run)
        c = self._choice_bits
        ok: np.ndarray = (c & ~allowed) == 0
        if open_moves:
            ok &= (open_moves & ~c) != 0
        return ok.astype(np.int8)

    def system_mask(self) -> np.ndarray:
        """``int8[n_actions]``: the system's legal actions now (with this step's restrictions)."""
        return self.game.action_mask(self.run)

    def synthesized_action(self) -> int:
        """The synthesized tester's action now: the agent's next state, or the bitmask of
        the synthesized restrictions of the system's state (static walls excluded)."""
        g, run = self.game, self.run
        if g.has_agent:
            return int(g.synthesized_agent_move(run)[0])
        return int(g.restricted_bits[run.history][run.system] & g.choosable_bits[run.system])

    def apply_tester(self, action: int) -> bool:
        """Play the tester's ``action`` on the run now (not an AEC step: no turn, reward or
        round bookkeeping). An action outside :meth:`tester_mask` is the no-op: restrict
        nothing, or the agent stays. Returns whether the action was legal.

        The exhaustive checks of :mod:`flowtest_env.fairness` play the tester through
        this method, so they follow exactly the rules of :meth:`step`.
        """
        g, run = self.game, self.run
        legal = self.tester_mask()
        ok = 0 <= action < legal.size and bool(legal[action])
        if g.has_agent:
            if ok:
                syn_agent, syn_memory = g.synthesized_agent_move(run)
                run.agent = action
                if action == syn_agent:
                    run.memory = syn_memory
        else:
            run.override = action if ok else 0
        return ok

    # ------------------------------------------------------------------ AEC API

    def tester_view(self) -> np.ndarray:
        """``float32[n]``: the tester's observation now, unpadded: one-hots of the system's
        state, the history, the test agent's state (and the strategy memory, where shown)."""
        run = self.run
        obs = np.zeros(self._n_tester_obs, dtype=np.float32)
        obs[run.system] = 1.0
        obs[self._n_states + run.history] = 1.0
        if run.agent >= 0:
            obs[self._n_states + self._n_hist + run.agent] = 1.0
        if self._n_memory and run.memory >= 0:
            obs[self._n_states + self._n_hist + self.game.n_agent_states + run.memory] = 1.0
        return obs

    def observe(self, agent: str) -> dict[str, np.ndarray]:
        """``{obs_key, mask_key}`` of ``agent`` now (see the module docstring)."""
        if agent == SYSTEM:
            obs, mask = self.encoder.encode(self.run), self.system_mask()
        else:
            obs, mask = self.tester_view(), self.tester_mask()
        if self.same_spaces:
            padded = np.zeros(self._padded_size, dtype=np.float32)
            flat = obs.reshape(-1)
            padded[: flat.size] = flat
            full = np.zeros(int(self._action_spaces[agent].n), dtype=np.int8)
            full[: mask.size] = mask
            obs, mask = padded, full
        return {self.obs_key: obs, self.mask_key: mask}

    def _info(self, agent: str) -> dict[str, Any]:
        """``agent``'s infos now (``info_kind``: see the module docstring)."""
        g, run = self.game, self.run
        if self.info_kind == "numeric":
            return {
                "system_state": int(run.system),
                "system_objective": OUTCOME_CODES[run.outcome],
                "test_objective_realized": int(bool(g.test_accepting[run.history])),
                "restrictions": int(run.restrictions),
                "blocked_attempts": int(run.blocked_attempts),
                "steps": int(run.steps),
            }
        info: dict[str, Any] = {"system_state": g.state_json(run.system)}
        if run.done or self.truncations.get(agent, False):
            info["verdict"] = g.verdict(run)
        return info

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None) -> None:
        """Start a run; the game has no randomness, so ``seed`` changes nothing."""
        self.agents = list(self.possible_agents)
        self.run = self.game.reset(agent_first_move=False)
        self.rewards = {a: 0.0 for a in self.agents}
        self._cumulative_rewards = {a: 0.0 for a in self.agents}
        self.terminations = {a: False for a in self.agents}
        self.truncations = {a: False for a in self.agents}
        self.infos = {a: self._info(a) for a in self.agents}
        self.agent_selection = self.agents[0]
        self._rounds = 0
        if self.render_mode == "human":
            self.render()

    def step(self, action: Any) -> None:
        """Play ``action`` for the selected agent (an illegal one is a penalized no-op)."""
        if not self.agents and not hasattr(self, "agent_selection"):
            raise gymnasium.error.ResetNeeded("call reset() before step()")
        agent = self.agent_selection
        if self.terminations[agent] or self.truncations[agent]:
            self._was_dead_step(action)
            return
        g, run = self.game, self.run
        self._cumulative_rewards[agent] = 0.0
        self.rewards = {x: 0.0 for x in self.agents}
        a = action_index(action, int(self._action_spaces[agent].n))
        if agent == TESTER:
            if not self.apply_tester(a):
                self.rewards[TESTER] -= self.config.restricted_penalty
        else:
            mask = self.system_mask()
            if not (0 <= a < mask.size and mask[a]):
                self.rewards[SYSTEM] -= self.config.restricted_penalty
            g.system_step(run, a if 0 <= a < g.n_actions else g.stay_action)
            self.rewards[SYSTEM] -= self.config.step_cost
            if run.done:
                if run.outcome == MET:
                    self.rewards[SYSTEM] += self.config.goal_reward
                    self.rewards[TESTER] += 1.0 if g.test_accepting[run.history] else -1.0
                elif run.outcome == VIOLATED:
                    self.rewards[SYSTEM] -= self.config.violation_penalty
                self.terminations = {x: True for x in self.agents}
        if agent == self.possible_agents[-1]:
            self._rounds += 1
            if self._rounds >= self.max_cycles and not run.done:
                self.truncations = {x: True for x in self.agents}
        for x in self.agents:
            self.infos[x] = self._info(x)
        self.agent_selection = self.agents[1] if agent == self.agents[0] else self.agents[0]
        self._accumulate_rewards()
        if self.render_mode == "human":
            self.render()

    @property
    def max_cycles(self) -> int:
        """Rounds before truncation (PettingZoo's name of ``config.max_steps``)."""
        assert self.config.max_steps is not None
        return self.config.max_steps

    def render(self) -> Any:
        """The run as ``render_mode`` asks: an RGB picture (``rgb_array``), text (``ansi``), or
        (``human``) that picture in a pygame window at ``render_fps`` frames a second,
        returning ``None``; in human mode :meth:`reset` and every :meth:`step` draw it too."""
        if self.render_mode is None:
            gymnasium.logger.warn("render() called without a render_mode")
            return None
        if self.render_mode == "ansi":
            return ansi(self.game, self.run, self.config.view)
        if self._renderer is None:
            self._renderer = make_renderer(self.game, self.config.tile_size, self.config.view)
        frame = self._renderer.frame(self.run)
        if self.render_mode != "human":
            return frame
        if self._window is None:
            self._window = HumanWindow(f"FlowTest: {self.problem}", int(self.metadata["render_fps"]))
        self._window.show(frame)
        return None

    def close(self) -> None:
        self._renderer = None
        if self._window is not None:
            self._window.close()
            self._window = None


class HumanWindow:
    """The window of ``render_mode="human"``: each RGB frame shown as it comes, at most
    ``fps`` a second (pygame, the ``render`` extra; ``SDL_VIDEODRIVER=dummy`` draws without a
    screen). Opened on the first frame, resized when a frame's size changes, closed by
    :meth:`close`."""

    def __init__(self, title: str, fps: int) -> None:
        self.title, self.fps = title, fps
        self._window: Any = None
        self._clock: Any = None

    def show(self, frame: np.ndarray) -> None:
        """Draw ``frame`` (``height x width x 3`` bytes) and let the window's events through."""
        import pygame

        size = (int(frame.shape[1]), int(frame.shape[0]))
        if self._window is None:
            pygame.display.init()
            pygame.display.set_caption(self.title)
            self._clock = pygame.time.Clock()
        if self._window is None or self._window.get_size() != size:
            self._window = pygame.display.set_mode(size)
        self._window.blit(pygame.surfarray.make_surface(np.transpose(frame, (1, 0, 2))), (0, 0))
        pygame.event.pump()
        self._clock.tick(self.fps)
        pygame.display.flip()

    def close(self) -> None:
        """Close the window (nothing to do if none was opened)."""
        if self._window is None:
            return
        import pygame

        pygame.display.quit()
        self._window = self._clock = None


class ParallelFlowTestEnv(ParallelEnv):  # type: ignore[misc]  # pettingzoo ships no type information
    """The parallel API over :class:`raw_env` (same arguments).

    A round applies the actions in turn order; when the run ends in the middle of a
    round (the system reached its goal before the tester's turn), the rest of the round
    is skipped. Every agent leaves ``agents`` at the end of the run.
    """

    metadata: dict[str, Any] = raw_env.metadata

    def __init__(self, **kwargs: Any) -> None:
        self.aec_env = raw_env(**kwargs)
        self.config: EnvConfig = self.aec_env.config
        self.possible_agents = list(self.aec_env.possible_agents)
        self.render_mode = self.aec_env.render_mode
        self.agents: list[str] = []

    def observation_space(self, agent: str) -> spaces.Dict:
        return self.aec_env.observation_space(agent)

    def action_space(self, agent: str) -> spaces.Discrete:
        return self.aec_env.action_space(agent)

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[dict[str, Any], dict[str, Any]]:
        self.aec_env.reset(seed=seed, options=options)
        self.agents = list(self.aec_env.agents)
        return {a: self.aec_env.observe(a) for a in self.agents}, {a: dict(self.aec_env.infos[a]) for a in self.agents}

    def step(self, actions: dict[str, Any]) -> tuple[dict[str, Any], dict[str, float], dict[str, bool], dict[str, bool], dict[str, Any]]:
        aec = self.aec_env
        if not self.agents:
            raise gymnasium.error.ResetNeeded("call reset() before step(): no agent is live (not reset, or the run has ended)")
        if not isinstance(actions, dict):
            raise gymnasium.error.InvalidAction(f"actions must be a dict {{agent: action}}, not {type(actions).__name__}")
        unknown = sorted(set(actions) - set(self.possible_agents), key=str)
        if unknown:
            raise gymnasium.error.InvalidAction(f"action for unknown agent {unknown[0]!r}; agents: {self.possible_agents}")
        for agent in self.agents:  # every live agent's action checked before any is played
            if agent not in actions:
                raise gymnasium.error.InvalidAction(f"no action for {agent}")
            action_index(actions[agent], int(aec.action_space(agent).n))
        rewards = {a: 0.0 for a in self.agents}
        for agent in self.possible_agents:
            if agent not in self.agents or aec.terminations[agent] or aec.truncations[agent]:
                break
            action = actions[agent]
            aec.agent_selection = agent
            aec.step(action)
            for a in rewards:
                rewards[a] += float(aec.rewards.get(a, 0.0))
        terminations = {a: bool(aec.terminations[a]) for a in self.agents}
        truncations = {a: bool(aec.truncations[a]) for a in self.agents}
        infos = {a: dict(aec.infos[a]) for a in self.agents}
        observations = {a: aec.observe(a) for a in self.agents}
        self.agents = [a for a in self.agents if not (terminations[a] or truncations[a])]
        if not self.agents:
            aec.agents = []
        else:
            aec.agent_selection = self.possible_agents[0]
        return observations, rewards, terminations, truncations, infos

    def render(self) -> Any:
        return self.aec_env.render()

    def close(self) -> None:
        self.aec_env.close()

    def state(self) -> np.ndarray:
        """The tester's full view of the run (system state, history, agent), flat and unpadded."""
        return self.aec_env.tester_view()


def _raw_of(e: Any) -> raw_env:
    """The :class:`raw_env` under ``e`` (an ``env()``, ``raw_env`` or ``parallel_env``,
    possibly wrapped: followed through ``aec_env``/``env``/``unwrapped``)."""
    raw, seen = e, 0
    while not isinstance(raw, raw_env):
        nxt = getattr(raw, "aec_env", None) or getattr(raw, "env", None) or getattr(raw, "_env", None)
        if nxt is None or seen > 32:
            raise TypeError(f"{type(e).__name__} is not a flowtest_env.multiagent environment")
        raw, seen = nxt, seen + 1
    return raw


def synthesized_tester(e: Any) -> Callable[..., int]:
    """The synthesized test strategy as a tester policy for ``e`` (an ``env()``,
    ``raw_env`` or ``parallel_env`` of this module).

    Returns a callable ``policy(observation=None, agent="tester_0") -> action`` that reads
    the run from the environment. For a policy a library holds apart from the env (a
    fixed policy in a multi-agent setup, many envs in a batch), use
    :class:`SynthesizedTester`: it answers from the tester's observation alone.
    """
    raw = _raw_of(e)

    def policy(observation: Any = None, agent: str = TESTER) -> int:
        return raw.synthesized_action()

    return policy


class SynthesizedTester:
    """The synthesized test strategy as a fixed policy over the tester's observation.

    Built once from any env of this module (it copies the strategy's tables, it keeps
    no reference to the env), then called with ``tester_0``'s observation: the Dict an
    env returns, its ``obs_key`` entry, or a batch ``[B, n]`` of them (NumPy or anything
    ``np.asarray`` takes, a CPU tensor included). The answer equals
    ``env.synthesized_action()`` whenever it is the tester's turn (tested on every
    built-in), so a multi-agent library can hold it as the tester's frozen policy while
    it trains ``system_0``. See docs/recipes.md for TorchRL and RLlib.

    Example
    -------
    >>> from flowtest_env import multiagent
    >>> e = multiagent.env(test="small-reactive")
    >>> tester = multiagent.SynthesizedTester(e)
    >>> e.reset(seed=0)
    >>> obs, *_ = e.last()
    >>> e.agent_selection, tester(obs) == e.unwrapped.synthesized_action()
    ('tester_0', True)
    """

    def __init__(self, env: Any) -> None:
        raw = _raw_of(env)
        g = raw.game
        self.obs_key = raw.obs_key
        self.n_states, self.n_hist, self.n_agent_states, self.n_memory = raw._n_states, raw._n_hist, g.n_agent_states, raw._n_memory
        self.n_tester_obs = raw._n_tester_obs
        self.controller = g.agent_controller if g.has_agent else None
        self._table: np.ndarray | None = None
        if self.controller is None:
            restricted = np.asarray(g.restricted_bits, dtype=np.int64)  # [history, state]
            choosable = np.asarray(g.choosable_bits, dtype=np.int64)  # [state]
            self._table = restricted & choosable[None, :]

    def actions(self, observations: Any) -> np.ndarray:
        """``int64[B]``: the synthesized tester's actions for a batch ``[B, n]`` of tester
        observations (padded ones too: the entries past the tester's own are ignored)."""
        obs = np.asarray(observations, dtype=np.float32)
        if obs.ndim != 2 or obs.shape[1] < self.n_tester_obs:
            raise ValueError(f"expected tester observations of shape [B, >={self.n_tester_obs}], got {obs.shape}")
        ns, nh, na = self.n_states, self.n_hist, self.n_agent_states
        system = np.argmax(obs[:, :ns], axis=1)
        history = np.argmax(obs[:, ns : ns + nh], axis=1)
        if self._table is not None:
            out: np.ndarray = self._table[history, system]
            return out
        assert self.controller is not None
        agent = np.argmax(obs[:, ns + nh : ns + nh + na], axis=1)
        if self.n_memory:
            memory = np.argmax(obs[:, ns + nh + na : ns + nh + na + self.n_memory], axis=1)
        else:
            memory = np.zeros(obs.shape[0], dtype=np.int64)
        respond = self.controller.respond
        return np.array([respond(int(a), int(m), int(s), int(h))[0] for a, m, s, h in zip(agent, memory, system, history, strict=True)], dtype=np.int64)

    def __call__(self, observation: Any, agent: str = TESTER) -> Any:
        """The action for one observation (an ``int``) or a batch (``int64[B]``);
        ``agent`` is accepted for the ``policy(obs, agent)`` shape and ignored."""
        if isinstance(observation, Mapping):
            observation = observation[self.obs_key]
        obs = np.asarray(observation)
        if obs.ndim == 1:
            return int(self.actions(obs[None, :])[0])
        return self.actions(obs)


__all__ = [
    "env",
    "raw_env",
    "parallel_env",
    "ParallelFlowTestEnv",
    "synthesized_tester",
    "SynthesizedTester",
    "TESTER",
    "SYSTEM",
    "INFO_KINDS",
    "NUMERIC_INFO_KEYS",
    "OUTCOME_CODES",
]
