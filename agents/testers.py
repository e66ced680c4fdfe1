"""Tester policies: who plays ``tester_0`` — the synthesized test or a learned one.

A *tester* answers the system under test inside the rules of the PettingZoo game
(:mod:`flowtest_env.multiagent`): on obstacle problems it chooses which moves of the
system's current state to restrict this step (a bitmask of the state's move slots; only
moves in the test harness that are not static walls, and never every move); on agent
problems it moves the test agent along its transition system, never into the system's
cell. :meth:`raw_env.tester_mask` is exactly that set of legal moves.

Testers are named like systems under test (:func:`make_tester`):

===================  ===================================================================
``synthesized``      the synthesized test strategy (FlowTest's test, with its guarantees)
``ppo:PATH``         a learned tester: a MaskablePPO model trained by
                     ``flowtest train-tester`` (:mod:`experiments.cli.train_tester`); a
                     folder ``PATH`` holds one per problem, ``PATH/<problem>.zip``
===================  ===================================================================

A learned tester is a stable-baselines3 zip, which loading unpickles (code from the file
runs): :func:`agents.ppo.load_model` loads it only when the user trusts it
(``--trust-model``, :func:`agents.checkpoint.trust_pickled_models`) or this process wrote
it, and raises :class:`agents.checkpoint.UntrustedModelError` otherwise.

A tester is a callable ``tester(env) -> action`` reading the run of a
:class:`~flowtest_env.multiagent.raw_env` (its tester observation: the system's state,
the history, the agent's place), deterministic, so :mod:`flowtest_env.fairness` can
search every run against it. Two single-agent Gymnasium views put a tester and a system
together:

* :class:`TesterView` — the tester is the learner, against a fixed system policy (for
  training a tester);
* :class:`VersusTesterEnv` — the system is the learner or the policy under test, against
  a given tester (what ``flowtest evaluate --tester ppo:PATH`` runs).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Protocol, SupportsFloat

import gymnasium as gym
import numpy as np

from flowtest_env.envs import DEFAULT_MAX_STEPS
from flowtest_env.fairness import can_still_meet
from flowtest_env.game import MET, RunState, TestGame
from flowtest_env.multiagent import SYSTEM, TESTER, raw_env

from .base import Policy, PolicyError
from .ppo import load_model
from .registry import make_policy

TESTER_ROLE = "tester"
"""The value of a learned tester model's ``flowtest_role`` attribute (a model trained as a
system under test has none)."""


class Tester(Protocol):
    """A deterministic tester: ``tester(env)`` answers the tester's action for the run of
    ``env`` (a :class:`raw_env`) now, without changing it."""

    name: str

    def __call__(self, env: raw_env) -> int: ...


class SynthesizedTester:
    """The synthesized test strategy (:meth:`raw_env.synthesized_action`)."""

    name = "synthesized"

    def __call__(self, env: raw_env) -> int:
        return env.synthesized_action()


class PPOTester:
    """A learned tester: a (Maskable)PPO model acting deterministically (its most likely
    legal action) on the tester's observation.

    Raises
    ------
    PolicyError
        If the model was not trained as a tester, or on a game with other spaces.
    """

    def __init__(self, model: Any, name: str, env: raw_env) -> None:
        if getattr(model, "flowtest_role", None) != TESTER_ROLE:
            raise PolicyError(f"model {name!r} is not a tester (train one with `flowtest train-tester`)")
        obs_shape = tuple(env.observation_space(TESTER)["observation"].shape or ())
        n = int(env.action_space(TESTER).n)
        if tuple(model.observation_space.shape) != obs_shape or int(model.action_space.n) != n:
            raise PolicyError(
                f"tester {name!r} was trained on {getattr(model, 'flowtest_problem', 'another problem')!r} "
                f"(observations {tuple(model.observation_space.shape)}, {int(model.action_space.n)} actions); "
                f"{env.problem!r} has {obs_shape} and {n}"
            )
        self.model = model
        self.name = name
        self.maskable = type(model).__name__ == "MaskablePPO"

    def __call__(self, env: raw_env) -> int:
        view = env.observe(TESTER)
        mask = view["action_mask"].astype(bool)
        if self.maskable:
            action, _ = self.model.predict(view["observation"], deterministic=True, action_masks=mask)
        else:
            action, _ = self.model.predict(view["observation"], deterministic=True)
        return int(np.asarray(action).item())


def make_tester(name: str, env: raw_env) -> Tester:
    """The tester called ``name`` for ``env`` (see the module docstring).

    Raises
    ------
    PolicyError
        On an unknown name, a missing model, or a model that does not fit ``env``.
    """
    name = name.strip()
    if name == "synthesized":
        return SynthesizedTester()
    if name.startswith("ppo:") and len(name) > 4:
        path = Path(name[4:])
        if path.is_dir():  # one learned tester per problem: DIR/<problem>.zip
            path = path / f"{env.problem}.zip"
            if not path.exists():
                raise PolicyError(f"no learned tester for {env.problem!r} in {name[4:]!r} (expected {str(path)!r})")
        return PPOTester(load_model(path), name, env)
    raise PolicyError(f"unknown tester {name!r}; known: synthesized, ppo:PATH")


def problem_of(env_id: str) -> tuple[str, int]:
    """``(problem, max_steps)`` of a registered built-in FlowTest env ID.

    Raises
    ------
    PolicyError
        If ``env_id`` is not a built-in problem's env (a learned tester plays one fixed game).
    """
    import flowtest_env  # noqa: F401  (registers the envs)

    spec = gym.spec(env_id) if env_id in gym.registry else None
    kwargs = dict(spec.kwargs) if spec is not None else {}
    problem = kwargs.get("test", kwargs.get("problem"))
    if not isinstance(problem, str):
        raise PolicyError(f"{env_id!r} is not a built-in problem's environment; a tester plays one fixed game")
    return str(problem), int(kwargs.get("max_steps") or DEFAULT_MAX_STEPS.get(problem, 100))


def _system_turn(env: raw_env) -> bool:
    return env.agents != [] and env.agent_selection == SYSTEM and not env.terminations[SYSTEM] and not env.truncations[SYSTEM]


def _tester_turn(env: raw_env) -> bool:
    return env.agents != [] and env.agent_selection == TESTER and not env.terminations[TESTER] and not env.truncations[TESTER]


class TesterView(gym.Env[np.ndarray, np.int64]):
    """The tester's single-agent view of the PettingZoo game against a fixed system policy
    (for training a tester).

    Observation: the tester's observation (one-hots of the system's state, the history
    and the agent's place); action: the tester's action; :meth:`action_masks` (and
    ``info["action_mask"]``) its legal moves. Reward: the PettingZoo tester's reward, +1
    when the system meets its objective with the test objective realized, -1 when it meets
    it without, and ``-trap_penalty`` when the round budget runs out with the system's
    objective still open (0 by default: a learned tester is rewarded only for what the test
    engineer asks, as in adversarial environment design; whether it traps is tracked,
    ``info["verdict"]`` at the end, and checked exhaustively by :mod:`flowtest_env.fairness`).
    """

    metadata: dict[str, Any] = {"render_modes": []}
    __test__ = False  # not a pytest class

    def __init__(self, problem: str, system: str = "scripted:replanner", max_cycles: int | None = None, trap_penalty: float = 0.0) -> None:
        self.ma = raw_env(problem=problem, max_cycles=max_cycles)
        self.problem = problem
        self.game: TestGame = self.ma.game
        self.system_name = system
        self.system: Policy = make_policy(system, self.ma)
        self.trap_penalty = float(trap_penalty)
        self.observation_space = self.ma.observation_space(TESTER)["observation"]
        self.action_space = self.ma.action_space(TESTER)

    @property
    def run(self) -> RunState:
        return self.ma.run

    def action_masks(self) -> np.ndarray:
        """``bool[n]``: the tester's legal actions now (for MaskablePPO)."""
        return self.ma.tester_mask().astype(bool)

    def _play_system(self) -> float:
        """Let the system act until it is the tester's turn or the run ended; its share
        of the tester's reward."""
        reward = 0.0
        while _system_turn(self.ma):
            obs = self.ma.observe(SYSTEM)
            self.ma.step(self.system.act(obs, self.ma.infos[SYSTEM]))
            reward += float(self.ma.rewards.get(TESTER, 0.0))
        return reward

    def _out(self, reward: float) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        view = self.ma.observe(TESTER)
        terminated = bool(self.ma.terminations.get(TESTER, False))
        truncated = bool(self.ma.truncations.get(TESTER, False)) and not terminated
        info: dict[str, Any] = {"action_mask": view["action_mask"]}
        if terminated or truncated:
            info["verdict"] = self.game.verdict(self.ma.run)
            if truncated:
                reward -= self.trap_penalty
        return view["observation"], reward, terminated, truncated, info

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        self.ma.reset(seed=seed)
        self.system.reset(seed)
        self._play_system()
        obs, _, _, _, info = self._out(0.0)
        return obs, info

    def step(self, action: Any) -> tuple[np.ndarray, SupportsFloat, bool, bool, dict[str, Any]]:
        if not _tester_turn(self.ma):
            raise gym.error.ResetNeeded("the run has ended; call reset()")
        self.ma.step(int(action))
        reward = float(self.ma.rewards.get(TESTER, 0.0)) + self._play_system()
        return self._out(reward)


class VersusTesterEnv(gym.Env[np.ndarray, np.int64]):
    """The system's single-agent view of the PettingZoo game against a given tester (what
    ``flowtest evaluate --tester NAME`` runs for a tester other than ``synthesized``).

    Spaces, observations, ``info`` (``action_mask``, ``system_state``, ``verdict`` at the
    end), :meth:`action_masks` and rewards are the system's, as in
    :class:`~flowtest_env.envs.FlowTestEnv`; the environment side is the tester. A run is
    truncated after ``max_steps`` rounds. :meth:`trapped` tells whether the run stopped
    where no system play can meet the objective against this tester any more.
    """

    metadata: dict[str, Any] = {"render_modes": ["rgb_array", "ansi"], "render_fps": 4}

    def __init__(
        self, problem: str, tester: str | Tester, max_steps: int | None = None, obs_kind: str = "flat", render_mode: str | None = None, view: str = "system"
    ) -> None:
        self.ma = raw_env(problem=problem, max_cycles=max_steps, obs_kind=obs_kind, render_mode=render_mode, view=view)
        self.problem = problem
        self.game: TestGame = self.ma.game
        self.encoder = self.ma.encoder
        self.tester: Tester = make_tester(tester, self.ma) if isinstance(tester, str) else tester
        self.render_mode = render_mode
        self.observation_space = self.ma.observation_space(SYSTEM)["observation"]
        self.action_space = self.ma.action_space(SYSTEM)

    @property
    def run(self) -> RunState:
        return self.ma.run

    def action_masks(self) -> np.ndarray:
        """``bool[n]``: the system's legal actions now."""
        return self.ma.system_mask().astype(bool)

    def _play_tester(self) -> None:
        while _tester_turn(self.ma):
            self.ma.step(self.tester(self.ma))

    def _info(self) -> dict[str, Any]:
        info = dict(self.ma.infos.get(SYSTEM, {}))
        info["action_mask"] = self.ma.system_mask()
        if self.ma.run.done or self.ma.truncations.get(SYSTEM, False):
            info["verdict"] = self.game.verdict(self.ma.run)
        return info

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        self.ma.reset(seed=seed)
        self._play_tester()
        return self.ma.observe(SYSTEM)["observation"], self._info()

    def step(self, action: Any) -> tuple[np.ndarray, SupportsFloat, bool, bool, dict[str, Any]]:
        if not _system_turn(self.ma):
            raise gym.error.ResetNeeded("the run has ended; call reset()")
        self.ma.step(int(action))
        reward = float(self.ma.rewards.get(SYSTEM, 0.0))
        self._play_tester()
        terminated = bool(self.ma.terminations.get(SYSTEM, False))
        truncated = bool(self.ma.truncations.get(SYSTEM, False)) and not terminated
        return self.ma.observe(SYSTEM)["observation"], reward, terminated, truncated, self._info()

    def trapped(self) -> bool:
        """Whether the run (ended) stopped where no sequence of legal system moves can
        meet the system objective against this tester, although the static walls would
        let the system through (:func:`flowtest_env.fairness.can_still_meet`)."""
        run = self.ma.run
        if run.outcome == MET or run.done:  # violated: the static walls doom it
            return False
        tester_next = self.ma.agent_selection == TESTER
        return not can_still_meet(self.ma, self.tester, run, tester_next)

    def render(self) -> Any:
        return self.ma.render()


__all__ = [
    "PPOTester",
    "SynthesizedTester",
    "Tester",
    "TesterView",
    "VersusTesterEnv",
    "make_tester",
    "problem_of",
    "TESTER_ROLE",
]
