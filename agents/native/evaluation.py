"""Greedy evaluation and batched play of a native agent: :func:`batch_verdicts` (a
deterministic policy plays every test once, all at once), :func:`met_rate` (the trainer's
greedy score), :class:`GreedyActor` and :class:`BatchActor` (an agent as a batched policy
of :mod:`flowtest_env.scoring`, greedy or sampled and seeded).

Example::

    from flowtest_env.scoring import score_policy
    from agents.native.evaluation import BatchActor
    greedy = score_policy(BatchActor(agent, where), pool="reachability1/5x5", split="test", count=1000)
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import torch

from flowtest_env.memory import first_memory, increment_of, remember
from flowtest_env.torch_memory import BatchPlaceMemory

from .agent import Agent, masked_logits

BatchAct = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
"""A deterministic batched policy: ``(observations with memory, bool masks, episode
starts) -> actions``; it keeps its own recurrent state."""


def batch_verdicts(
    act: BatchAct, games: Sequence[Any], budgets: Sequence[int], where: slice | None, obs_kind: str = "flat", seed: int = 0, memory: str = "visited"
) -> dict[str, np.ndarray]:
    """Let a deterministic policy play every test of ``games`` once, all at once in one
    :class:`~flowtest_env.vector.PoolVectorEnv` (env ``i`` plays test ``i``), and return
    the verdict arrays: ``system_objective`` (``"met"``, ``"violated"``, ``"open"``),
    ``test_objective_realized``, ``restrictions``, ``steps``. Each test ends where the
    single env ends it: at its outcome or at its own step budget ``budgets[i]``.
    ``where``: the SUT's place in the observation, for the place memory of kind ``memory``
    (``"visited"`` or ``"counts"``; ``where=None``: no memory).
    """
    from flowtest_env.scoring import play_batch

    played = play_batch(WithVisited(act, where, memory), games, runs=1, seed=seed, obs_kind=obs_kind, budgets=budgets)
    return {key: values[0] for key, values in played.items()}


class WithVisited:
    """A :data:`BatchAct` as a batched policy (``policy(obs, masks)`` with ``reset``) of
    :func:`flowtest_env.scoring.play_batch`: it feeds the policy the observation with the
    place memory of kind ``memory`` appended (the SUT's places seen so far, ``where`` in the
    observation; ``None``: no memory) and the episode-start flags of its first step."""

    def __init__(self, act: BatchAct, where: slice | None, memory: str = "visited") -> None:
        self.act, self.where = act, where
        self.increment = increment_of(memory) if where is not None else 1.0
        self.seen: np.ndarray | None = None
        self.starts = np.ones(0, dtype=bool)

    def reset(self, n: int, seed: int) -> None:
        self.seen, self.starts = None, np.ones(n, dtype=bool)

    def __call__(self, obs: np.ndarray, masks: np.ndarray) -> np.ndarray:
        x = obs
        if self.where is not None:
            now = obs[:, self.where].astype(np.float32)
            self.seen = first_memory(now, self.increment) if self.seen is None else remember(self.seen, now, self.increment)
            x = np.concatenate([obs.astype(np.float32), self.seen], axis=1)
        actions = np.asarray(self.act(x, masks, self.starts))
        self.starts = np.zeros(len(obs), dtype=bool)
        return actions


class GreedyActor:
    """The agent's most likely legal action for a batch, carrying the GRU state."""

    def __init__(self, agent: Agent, device: torch.device) -> None:
        self.agent, self.device = agent, device
        self.h: torch.Tensor | None = None

    def __call__(self, x: np.ndarray, masks: np.ndarray, starts: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            xt = torch.as_tensor(np.asarray(x, dtype=np.float32), device=self.device)
            st = torch.as_tensor(np.asarray(starts, dtype=bool), device=self.device)
            if self.h is None or self.h.shape[0] != xt.shape[0]:
                self.h = self.agent.initial_state(xt.shape[0], self.device)
            logits, self.h = self.agent.policy_logits(xt, self.h, st)
            logits = masked_logits(logits, torch.as_tensor(np.asarray(masks, dtype=bool), device=self.device))
            out: np.ndarray = torch.argmax(logits, dim=-1).cpu().numpy()
            return out


class BatchActor:
    """A native agent as a batched policy of :mod:`flowtest_env.scoring`:
    ``actor(observations, masks) -> actions`` on the env's own observations (the actor adds
    the visited-places memory itself when the agent was trained with it, and carries the
    GRU state; ``memory``: the memory's kind, ``"visited"`` or ``"counts"``). ``deterministic``:
    the most likely legal action (greedy); otherwise one
    sampled from the masked policy with a torch generator that ``reset(n, seed)`` seeds,
    so the same seed gives the same runs.

    Example::

        from flowtest_env.scoring import score_policy
        model = load_native("policy.zip")
        greedy = score_policy(model.batch_policy(), pool="reachability1/5x5", split="test", count=1000)
        sampled = score_policy(model.batch_policy(deterministic=False), pool="reachability1/5x5", split="test",
                               count=1000, runs=8)
    """

    def __init__(self, agent: Agent, where: slice | None, deterministic: bool = True, device: str | torch.device = "cpu", memory: str = "visited") -> None:
        self.agent, self.where, self.deterministic, self.memory_kind = agent, where, deterministic, memory
        self.device = torch.device(device)
        self.memory = self._new_memory()
        self.h: torch.Tensor | None = None
        self.start = True
        self.generator = torch.Generator(device=self.device).manual_seed(0)

    def reset(self, num_runs: int, seed: int) -> None:
        """Before a batch of runs: forget the memory and the GRU state; seed the sampling."""
        self.memory = self._new_memory()
        self.h = None
        self.start = True
        self.generator = torch.Generator(device=self.device).manual_seed(int(seed))

    def _new_memory(self) -> BatchPlaceMemory | None:
        return BatchPlaceMemory(self.where, self.memory_kind) if self.where is not None else None

    def __call__(self, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            obs = torch.as_tensor(np.asarray(observations, dtype=np.float32), device=self.device)
            n = obs.shape[0]
            start = torch.full((n,), self.start, dtype=torch.bool, device=self.device)
            self.start = False
            x = obs if self.memory is None else self.memory(obs, start)
            if self.h is None or self.h.shape[0] != n:
                self.h = self.agent.initial_state(n, self.device)
            logits, self.h = self.agent.policy_logits(x, self.h, start)
            logits = masked_logits(logits, torch.as_tensor(np.asarray(masks, dtype=bool), device=self.device))
            if self.deterministic:
                a = torch.argmax(logits, dim=-1)
            else:
                u = torch.rand(logits.shape, generator=self.generator, device=self.device).clamp_(1e-12, 1.0)
                a = torch.argmax(logits - torch.log(-torch.log(u)), dim=-1)
            out: np.ndarray = a.cpu().numpy()
            return out


def met_rate(
    agent: Agent, games: Sequence[Any], budgets: Sequence[int], where: slice | None, obs_kind: str, device: torch.device, memory: str = "visited"
) -> dict[str, float]:
    """Greedy play of every test once: the share met and realized (of all tests), mean restrictions."""
    was = agent.training
    agent.eval()
    v = batch_verdicts(GreedyActor(agent, device), games, budgets, where, obs_kind, memory=memory)
    agent.train(was)
    met = v["system_objective"] == "met"
    return {"met": float(met.mean()), "realized": float((met & v["test_objective_realized"]).mean()), "restrictions": float(v["restrictions"].mean())}


__all__ = ["BatchAct", "BatchActor", "GreedyActor", "WithVisited", "batch_verdicts", "met_rate"]
