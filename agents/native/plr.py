"""Prioritized level replay for the native trainer: :class:`LevelSampler` chooses each
episode's test (level) of a pool vector env by its learning potential, and
:func:`level_sampler` installs it (``NativeArgs(level_sampling="plr")``).

Example::

    from agents.native.plr import LevelSampler
    sampler = LevelSampler(n_levels=128, score="pvl", temperature=0.1, staleness=0.1, seed=0)
    env.set_test_chooser(sampler.choose)            # a flowtest_env.vector.PoolVectorEnv
    sampler.update(levels, advantages, valid, starts)  # after each rollout
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .args import PLR_SCORES, NativeArgs


class LevelSampler:
    """Prioritized level replay over a fixed set of training tests (levels), after Jiang,
    Grefenstette and Rocktäschel, *Prioritized Level Replay*, ICML 2021 (written from the
    paper's description).

    Each level has a **score**, the learning potential its last run showed: ``"pvl"``, the
    positive value loss (the mean over the run's steps of ``max(A_t, 0)``, ``A_t`` the GAE
    advantage), or ``"gae"``, the mean of ``|A_t|``; and a **staleness**, the episodes
    started since it was last chosen. When an episode starts, its level is

    * with probability ``seen / n_levels`` (the share of levels played so far, the paper's
      replay decision for a finite training set) a **replay**: drawn from
      ``P = (1 - rho) * P_S + rho * P_C`` over the seen levels, where ``P_S`` is the
      rank-based prioritization ``h_i^(1/beta) / sum_j h_j^(1/beta)`` with ``h_i = 1 /
      rank(score_i)`` (rank 1: the highest score) and ``P_C`` is proportional to the
      staleness;
    * otherwise a level never played, uniformly.

    ``beta`` is ``temperature``, ``rho`` is ``staleness``. Scores are updated after each
    rollout from the runs it holds (a run cut by the rollout's end is scored on the steps so
    far, and rescored by the next rollout). Seeded: the same seed and scores give the same
    levels.
    """

    def __init__(self, n_levels: int, score: str = "pvl", temperature: float = 0.1, staleness: float = 0.1, seed: int = 0) -> None:
        if n_levels < 1:
            raise ValueError("level sampling needs at least one level")
        if score not in PLR_SCORES:
            raise ValueError(f"unknown plr_score {score!r}; expected one of {', '.join(PLR_SCORES)}")
        self.n = int(n_levels)
        self.score_kind = score
        self.temperature, self.staleness = float(temperature), float(staleness)
        self.scores = np.zeros(self.n, dtype=np.float64)
        self.seen = np.zeros(self.n, dtype=bool)
        self.last = np.zeros(self.n, dtype=np.int64)  # the episode count when each level was last chosen
        self.episodes = 0
        self.replays = 0
        self.rng = np.random.default_rng(seed)

    def replay_distribution(self) -> np.ndarray:
        """``float[n_levels]``: the replay probabilities (0 for levels never played)."""
        p = np.zeros(self.n, dtype=np.float64)
        idx = np.flatnonzero(self.seen)
        if idx.size == 0:
            return p
        order = np.argsort(-self.scores[idx], kind="stable")
        rank = np.empty(idx.size, dtype=np.float64)
        rank[order] = np.arange(1, idx.size + 1)
        ps = (1.0 / rank) ** (1.0 / self.temperature)
        ps /= ps.sum()
        stale = (self.episodes - self.last[idx]).astype(np.float64)
        pc = stale / stale.sum() if stale.sum() > 0 else np.full(idx.size, 1.0 / idx.size)
        p[idx] = (1.0 - self.staleness) * ps + self.staleness * pc
        out: np.ndarray = p / p.sum()
        return out

    def choose(self, envs: np.ndarray) -> np.ndarray:
        """The levels of the episodes starting now in ``envs`` (one each)."""
        k = int(np.asarray(envs).size)
        out = np.zeros(k, dtype=np.int64)
        if k == 0:
            return out
        unseen = np.flatnonzero(~self.seen)
        replay = self.rng.random(k) < (self.n - unseen.size) / self.n
        if unseen.size == 0:
            replay[:] = True
        n_replay = int(replay.sum())
        if n_replay:
            out[replay] = self.rng.choice(self.n, size=n_replay, p=self.replay_distribution())
        if k - n_replay:
            out[~replay] = self.rng.choice(unseen, size=k - n_replay)
        self.replays += n_replay
        self.episodes += k
        self.last[out] = self.episodes
        return out

    def update(self, levels: np.ndarray, adv: np.ndarray, valid: np.ndarray, starts: np.ndarray) -> None:
        """Score the levels of a rollout's runs (arrays ``[T, N]``: the level of each step,
        the GAE advantages, the valid steps, the episodes' first steps)."""
        T, N = adv.shape
        seg = np.cumsum(np.asarray(starts, dtype=np.int64), axis=0)  # which run of env i a step belongs to
        key = (np.arange(N)[None, :] * (T + 1) + seg)[valid]
        a = np.asarray(adv, dtype=np.float64)[valid]
        value = np.maximum(a, 0.0) if self.score_kind == "pvl" else np.abs(a)
        sums = np.bincount(key, weights=value, minlength=N * (T + 1))
        counts = np.bincount(key, minlength=N * (T + 1))
        level_of = np.zeros(N * (T + 1), dtype=np.int64)
        level_of[key] = np.asarray(levels, dtype=np.int64)[valid]
        runs = np.flatnonzero(counts)
        self.scores[level_of[runs]] = sums[runs] / counts[runs]
        self.seen[level_of[runs]] = True

    def stats(self) -> dict[str, float]:
        """For the log: levels seen, the share of replays, the mean score of the seen levels."""
        seen = int(self.seen.sum())
        return {
            "levels_seen": float(seen),
            "replay_share": self.replays / max(1, self.episodes),
            "mean_score": float(self.scores[self.seen].mean()) if seen else 0.0,
        }


def level_sampler(args: NativeArgs, env: Any, n_levels: int) -> LevelSampler | None:
    """With ``level_sampling="plr"``: a :class:`LevelSampler` over the env's tests, made
    the chooser of every episode's test in ``env`` (a :class:`~flowtest_env.vector.PoolVectorEnv`);
    ``None`` otherwise.

    Raises
    ------
    ValueError
        If the env cannot have its tests chosen (not a pool env of the NumPy backend).
    """
    if args.level_sampling != "plr":
        return None
    if n_levels < 1 or not hasattr(env, "set_test_chooser") or not hasattr(env, "test_index"):
        raise ValueError(f"level_sampling 'plr' needs a pool vector env of the NumPy backend, not {type(env).__name__}")
    sampler = LevelSampler(n_levels, args.plr_score, args.plr_temperature, args.plr_staleness, args.seed)
    env.set_test_chooser(sampler.choose)
    return sampler


__all__ = ["LevelSampler", "level_sampler"]
