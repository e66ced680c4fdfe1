"""Saved models played in batches: every test of a split at once in one vector env, greedy or
sampled (what the learning curves and the scores of the baselines read). The batched policy of
a stable-baselines3 model is :class:`agents.ppo.ModelBatchPolicy`."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from agents.ppo import ModelBatchPolicy, model_where

from .config import RUN_SEED

__all__ = ["CurveRecorder", "ModelBatchPolicy", "batch_verdicts", "model_where"]


def batch_verdicts(model: Any, games: Sequence[Any], memory: str, budgets: Sequence[int]) -> dict[str, np.ndarray]:
    """Let the deterministic policy of ``model`` (a saved model as :func:`agents.ppo.load_model`
    gives it: native or stable-baselines3) play every test of ``games`` once, all at once in
    one :class:`~flowtest_env.vector.PoolVectorEnv`, and return the verdict arrays
    (``system_objective``, ``test_objective_realized``, ``restrictions``, ``steps``), one
    entry per test. Each test ends at its outcome or its own step budget ``budgets[i]``
    (the tests' :func:`~flowtest_env.envs.default_max_steps`, which the batch uses).

    Raises
    ------
    ValueError
        If the tests do not share where the observation holds the system's place.
    """
    from flowtest_env.envs import default_max_steps
    from flowtest_env.scoring import play_batch

    if list(budgets) != [default_max_steps(g) for g in games]:
        raise ValueError("the batch plays each test to its own default step budget")
    policy = ModelBatchPolicy(model, model_where(model, games, memory), deterministic=True)
    return {k: v[0] for k, v in play_batch(policy, games, 1, RUN_SEED).items()}


class CurveRecorder:
    """An SB3 callback that measures the learning curve: the share of the train tests and
    of the validation tests whose system objective the deterministic policy meets
    (:func:`batch_verdicts`), for the model as it is after learning from ``step`` time
    steps: at the start, at the first rollout after every ``every`` steps, and at the end.
    It only reads the model: training goes exactly as without it.

    With ``keep``, every measurement whose validation met is at least the best so far (the
    latest of equals) calls ``keep(model)`` (which saves it) and records its step in
    ``kept_step``: the run's checkpoint selected by validation."""

    def __init__(self, every: int, memory: str, splits: dict[str, tuple[list[Any], list[int]]], keep: Callable[[Any], None] | None = None) -> None:
        from stable_baselines3.common.callbacks import BaseCallback

        recorder = self
        self.points: list[tuple[int, dict[str, float]]] = []
        self.seconds = 0.0
        self.kept_step: int | None = None
        best = [-1.0]

        def measure(model: Any, step: int) -> None:
            t0 = time.perf_counter()
            rates = {}
            for name, (games, budgets) in splits.items():
                v = batch_verdicts(model, games, memory, budgets)
                rates[name] = float(np.mean(v["system_objective"] == "met"))
            recorder.points.append((step, rates))
            if keep is not None and rates.get("validation", -1.0) >= best[0]:
                best[0] = rates["validation"]
                keep(model)
                recorder.kept_step = step
            recorder.seconds += time.perf_counter() - t0

        class Callback(BaseCallback):
            def __init__(self) -> None:
                super().__init__()
                self.next = 0

            def _on_rollout_start(self) -> None:  # the model has learned from num_timesteps steps
                if self.num_timesteps >= self.next:
                    measure(self.model, self.num_timesteps)
                    while self.next <= self.num_timesteps:
                        self.next += every

            def _on_step(self) -> bool:
                return True

            def _on_training_end(self) -> None:
                measure(self.model, self.num_timesteps)

        self.callback = Callback()
