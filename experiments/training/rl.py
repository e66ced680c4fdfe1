"""What training a system (:mod:`experiments.training.system`) and a tester
(:mod:`experiments.training.tester`) share: the ``rl`` extra, the PPO model, the timed
training call and its learning curve.

Both learners are sb3-contrib PPO models trained on a few envs stepped in one process;
the curve (:class:`EpisodeCurve`) records every episode end of every training env with
the verdict of the run, so each command plots and saves what it cares about (the
system's success, or the tester's realized-before-goal and unfinished runs) from the
same records.
"""

from __future__ import annotations

import importlib.util
import sys
import time
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from synthesis.model.errors import ProblemError

RL_MODULES = ("torch", "stable_baselines3", "sb3_contrib")
"""The modules of the ``rl`` extra."""


def rl_installed() -> bool:
    """Whether the ``rl`` extra (torch, stable-baselines3, sb3-contrib) is installed."""
    return all(importlib.util.find_spec(m) is not None for m in RL_MODULES)


def require_rl() -> None:
    """Refuse, as invalid input, to train without the ``rl`` extra.

    Raises
    ------
    ProblemError
        If stable-baselines3 or sb3-contrib cannot be imported.
    """
    try:
        import sb3_contrib  # noqa: F401
        import stable_baselines3  # noqa: F401
    except ImportError:
        raise ProblemError("training needs the rl extra: pip install 'flowtest[rl]'") from None


def require_native() -> None:
    """Refuse, as invalid input, to train natively without torch.

    Raises
    ------
    ProblemError
        If torch cannot be imported.
    """
    try:
        import torch  # noqa: F401
    except ImportError:
        raise ProblemError("training needs the rl extra: pip install 'flowtest[rl]'") from None


def make_ppo(env: Any, settings: dict[str, Any], seed: int, recurrent: bool = False) -> Any:
    """A ``MaskablePPO`` (MLP policy, action masks) or, with ``recurrent``, a
    ``RecurrentPPO`` (LSTM policy) on ``env`` with the algorithm's ``settings``
    (``n_steps``, ``batch_size``, ``learning_rate``, ``gamma``, ``ent_coef``, ``n_epochs``,
    ``net_arch``, and ``lstm_hidden_size`` when recurrent): on the CPU, one torch thread,
    seeded, so a seed gives the same model."""
    import torch
    from sb3_contrib import MaskablePPO, RecurrentPPO

    torch.manual_seed(seed)
    torch.set_num_threads(1)
    cls, policy = (RecurrentPPO, "MlpLstmPolicy") if recurrent else (MaskablePPO, "MlpPolicy")
    policy_kwargs: dict[str, Any] = {"net_arch": list(settings["net_arch"])}
    if recurrent:
        policy_kwargs["lstm_hidden_size"] = int(settings["lstm_hidden_size"])
    return cls(
        policy,
        env,
        seed=seed,
        verbose=0,
        device="cpu",
        n_steps=settings["n_steps"],
        batch_size=settings["batch_size"],
        learning_rate=settings["learning_rate"],
        gamma=settings["gamma"],
        ent_coef=settings["ent_coef"],
        n_epochs=settings["n_epochs"],
        policy_kwargs=policy_kwargs,
    )


@dataclass(frozen=True)
class EpisodeEnd:
    """One finished training episode, as the env's verdict saw it."""

    step: int
    """Time steps taken (all training envs together) when it ended."""
    met: bool
    """The system objective was met."""
    realized: bool
    """The test objective was realized."""
    ret: float
    """The learner's return: its rewards over the episode, summed."""


class EpisodeCurve:
    """The learning curve: an :class:`EpisodeEnd` at every episode end of every training
    env (``points``), recorded by an SB3 callback (``callback``)."""

    def __init__(self) -> None:
        from stable_baselines3.common.callbacks import BaseCallback

        points: list[EpisodeEnd] = []

        class Callback(BaseCallback):
            def __init__(self) -> None:
                super().__init__()
                self.ret: np.ndarray | None = None

            def _on_step(self) -> bool:
                rewards, dones, infos = self.locals["rewards"], self.locals["dones"], self.locals["infos"]
                if self.ret is None:
                    self.ret = np.zeros(len(rewards))
                self.ret += rewards
                for i in np.flatnonzero(dones):
                    verdict = infos[i].get("verdict", {})
                    points.append(
                        EpisodeEnd(
                            step=self.num_timesteps,
                            met=verdict.get("system_objective") == "met",
                            realized=bool(verdict.get("test_objective_realized")),
                            ret=float(self.ret[i]),
                        )
                    )
                    self.ret[i] = 0.0
                return True

        self.points = points
        self.callback = Callback()


def moving_average(values: list[float], window: int = 20) -> np.ndarray:
    """Means over ``window`` consecutive values (fewer when there are fewer values); one
    per full window, so value ``k`` of the result ends at value ``k + window - 1``."""
    win = min(window, len(values))
    return np.convolve(values, np.ones(win) / win, mode="valid")


def _progress_callback(total: int) -> Any:
    """A tqdm progress bar on stderr as an SB3 callback (SB3's own needs ``rich`` too)."""
    from stable_baselines3.common.callbacks import BaseCallback
    from tqdm import tqdm

    class Bar(BaseCallback):
        def _on_training_start(self) -> None:
            self.bar = tqdm(total=total, unit="step", desc="training", file=sys.stderr, mininterval=1.0)

        def _on_step(self) -> bool:
            self.bar.update(self.num_timesteps - self.bar.n)  # one call per step of all envs
            return True

        def _on_training_end(self) -> None:
            self.bar.close()

    return Bar()


class Recorder(Protocol):
    """What :func:`learn` records with: an SB3 callback (:class:`EpisodeCurve`, or the
    held-out learning curve of ``flowtest benchmark``)."""

    callback: Any


def learn(model: Any, steps: int, curve: Recorder, progress_bar: bool) -> float:
    """Train ``model`` for ``steps`` time steps, recording ``curve`` (and showing a progress
    bar on stderr when asked); the seconds it took."""
    t0 = time.perf_counter()
    callbacks = [curve.callback] + ([_progress_callback(steps)] if progress_bar else [])
    model.learn(total_timesteps=steps, callback=callbacks)
    return time.perf_counter() - t0


def action_masks_of(env: Any) -> Any:
    """The legal-action mask of a FlowTest env under its wrappers (``ActionMasker``'s function)."""
    return env.unwrapped.action_masks()
