"""Score any batched policy on a test pool by the benchmark's protocol, and the protocol's
statistics (docs/benchmark-protocol.md).

A **batched policy** is a callable from a batch of observations and action masks to
actions::

    actions = policy(observations, masks)   # float/uint8 [n, obs], bool [n, n_actions] -> int [n]

It may also have ``reset(num_runs, seed)``, called once before a batch of runs starts (each
row of the batch then plays one run from its first observation, so a recurrent policy
knows where its episodes begin). Every run of every test is played at once in one
:class:`~flowtest_env.vector.PoolVectorEnv` (``assignment="fixed"``: row ``i`` plays test
``i % n_tests``, run ``i // n_tests``), each ending where the single env would end it: at
its outcome or at its own step budget. So scoring 1,000 tests x 8 runs is one batch of
8,000 rows, seconds on a CPU::

    import numpy as np
    from flowtest_env.scoring import score_policy

    def first_legal(observations, masks):
        return np.argmax(masks, axis=1)

    score = score_policy(first_legal, pool="reachability1/5x5", split="test", count=100, runs=1)
    score.met, score.realized, score.per_test_met[:5]

A policy that draws random actions is played ``runs`` times per test (seeded: run ``k``
of the batch gets ``seed`` through ``reset``); a deterministic (greedy) one needs one run.
:func:`random_policy` is the protocol's floor. The references (the scripted replanner and
the GR(1) system) are not batched: ``flowtest benchmark`` plays them through the single env.

The statistics (:func:`score_interval`: the normalized score with its seed-and-test bootstrap
or, below :data:`PRELIMINARY_SEEDS` seeds, its t interval; :func:`tail_score`: the CVaR of the
per-test met shares, a point without an interval; :func:`crossed_draws`, :func:`iqm`, :func:`worst_share_mean`,
:func:`normalized`) are plain NumPy, seeded, and documented with their choices in
docs/benchmark-protocol.md. This module imports neither torch nor the agents.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any, Protocol

import numpy as np

from .envs import default_max_steps
from .game import TestGame

__all__ = [
    "PRELIMINARY_SEEDS",
    "TAIL_SHARE",
    "BatchPolicy",
    "PolicyScore",
    "PoolSource",
    "ScoreInterval",
    "TailScore",
    "crossed_draws",
    "iqm",
    "load_tests",
    "normalized",
    "play_batch",
    "random_policy",
    "score_interval",
    "score_policy",
    "seed_iqm",
    "summarize",
    "tail_score",
    "worst_share_mean",
]


class BatchPolicy(Protocol):
    """``policy(observations, masks) -> actions`` for a batch (module docstring)."""

    def __call__(self, observations: np.ndarray, masks: np.ndarray) -> np.ndarray: ...


PoolSource = Callable[[str, str, int], Sequence[Any]]
"""Where the tests of a pool come from: ``source(pool, split, count)`` returns the first
``count`` tests of the split (artifacts or :class:`~flowtest_env.game.TestGame`). The
default is :func:`flowtest_env.pools.load_pool`; a caller with its own records passes its
own loader."""


def _default_source(pool: str, split: str, count: int) -> Sequence[Any]:
    from .pools import load_pool

    return load_pool(pool, split, count, progress=False)


def load_tests(pool: str, split: str, count: int, source: PoolSource | None = None) -> list[TestGame]:
    """The first ``count`` tests of a pool's split as games, from ``source`` (default:
    :func:`flowtest_env.pools.load_pool`).

    Raises
    ------
    ValueError
        On a bad pool name, split or count (the source's own error).
    """
    tests = (source or _default_source)(pool, split, count)
    return [t if isinstance(t, TestGame) else TestGame(t) for t in tests]


# --------------------------------------------------------------------------- playing


def play_batch(
    policy: Callable[[np.ndarray, np.ndarray], Any],
    games: Sequence[TestGame],
    runs: int = 1,
    seed: int = 0,
    obs_kind: str = "flat",
    budgets: Sequence[int] | None = None,
    options: Mapping[str, Any] | None = None,
) -> dict[str, np.ndarray]:
    """Play ``runs`` runs of every test of ``games`` with ``policy``, all at once in one
    :class:`~flowtest_env.vector.PoolVectorEnv`, and return the verdict arrays, each of
    shape ``[runs, n_tests]``: ``system_objective`` (``"met"``, ``"violated"``,
    ``"open"``), ``test_objective_realized``, ``restrictions``, ``steps``.

    Each run ends where the single env ends it: at its outcome, or at its test's own step
    budget (``budgets[i]``; by default :func:`flowtest_env.envs.default_max_steps`,
    ``"open"``). ``options``: more env options of the batch's observations, those the
    policy was trained with (``{"memory": "visited"}``; an ``obs_kind`` there wins).
    ``policy.reset(n,
    seed)`` is called first when the policy has it; rows keep stepping after their run ended
    (their actions no longer matter) until every run has ended.

    Raises
    ------
    ValueError
        If ``runs < 1``, there is no test, or the policy answers a batch of the wrong shape.
    """
    if runs < 1:
        raise ValueError(f"runs must be at least 1, not {runs}")
    if not games:
        raise ValueError("no test to play")
    t = len(games)
    n = runs * t
    steps = [default_max_steps(g) for g in games] if budgets is None else list(budgets)
    if len(steps) != t:
        raise ValueError(f"{len(steps)} step budgets for {t} tests")
    limit = np.tile(np.asarray(steps, dtype=np.int64), runs)
    env = batch_env(games, n, obs_kind, options)  # kept for the next batch of the same tests
    reset = getattr(policy, "reset", None)
    if callable(reset):
        reset(n, seed)
    obs, infos = env.reset(seed=seed)
    done = np.zeros(n, dtype=bool)
    result: dict[str, np.ndarray] = {
        "system_objective": np.full(n, "open", dtype=object),
        "test_objective_realized": np.zeros(n, dtype=bool),
        "restrictions": np.zeros(n, dtype=np.int64),
        "steps": np.zeros(n, dtype=np.int64),
    }
    while not done.all():
        actions = np.asarray(policy(obs, infos["action_mask"].astype(bool)))
        if actions.shape != (n,):
            raise ValueError(f"the policy answered actions of shape {actions.shape} for a batch of {n}")
        obs, _, terminated, _, infos = env.step(actions.astype(np.int64))
        now = env.verdicts()
        ended = ~done & (terminated | (now["steps"] >= limit))
        for key, values in result.items():
            values[ended] = now[key][ended]
        done |= ended
    return {k: v.reshape(runs, t) for k, v in result.items()}


_ENVS: dict[tuple[Any, ...], tuple[Sequence[TestGame], Any]] = {}
ENV_CACHE_SIZE = 8
"""How many batch envs :func:`batch_env` keeps (compiling 1,000 tests takes seconds; a
benchmark plays the same tests with many policies)."""


def batch_env(games: Sequence[TestGame], num_envs: int, obs_kind: str = "flat", options: Mapping[str, Any] | None = None) -> Any:
    """A :class:`~flowtest_env.vector.PoolVectorEnv` of ``num_envs`` rows playing ``games``
    with ``assignment="fixed"`` (row ``i`` plays test ``i % len(games)``), each row's step
    budget the largest test's (:func:`play_batch` ends each run at its own), with the env
    ``options`` given (the observation's: ``memory``, ``pad_to``). The env is kept
    (the last :data:`ENV_CACHE_SIZE`, keyed by the very game objects, which the cache keeps
    alive) and reused: every batch starts with ``reset(seed=...)``, which restarts every row."""
    from .vector import PoolVectorEnv

    more = dict(options or {})
    key = (tuple(id(g) for g in games), int(num_envs), obs_kind, tuple(sorted(more.items())))
    hit = _ENVS.pop(key, None)
    if hit is None:
        budget = max(default_max_steps(g) for g in games)
        hit = (list(games), PoolVectorEnv(num_envs, list(games), assignment="fixed", max_steps=budget, **{"obs_kind": obs_kind, **more}))
    _ENVS[key] = hit  # the most recent last
    while len(_ENVS) > ENV_CACHE_SIZE:
        _, old = _ENVS.pop(next(iter(_ENVS)))  # the least recently used
        old.close()
    return hit[1]


class random_policy:  # noqa: N801 - used like a function: random_policy(seed)
    """The protocol's floor: uniform over the legal actions of each row, seeded (a row
    without a legal action gets action 0). ``reset(n, seed)`` restarts its generator, so
    the same seed gives the same runs.

    Example::

        score_policy(random_policy(), pool="reachability1/5x5", split="test", count=1000, runs=8)
    """

    def __init__(self, seed: int = 0) -> None:
        self.rng = np.random.default_rng(seed)

    def reset(self, num_runs: int, seed: int) -> None:
        self.rng = np.random.default_rng(seed)

    def __call__(self, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
        u = self.rng.random(masks.shape)
        out: np.ndarray = np.argmax(np.where(masks, u, -1.0), axis=1)
        return out


# --------------------------------------------------------------------------- the result


@dataclass(frozen=True)
class PolicyScore:
    """A policy's score on tests, by the protocol (:func:`score_policy`); JSON by
    :meth:`to_json`.

    Attributes
    ----------
    tests, runs, seed
        How many tests, runs per test, and the seed of the batch.
    met
        Share of all runs whose system objective was met.
    realized
        Share of the met runs that also realized the hidden test objective (a synthesized
        test guarantees 1.0); ``None`` when no run met.
    restrictions
        Mean restricted decisions per run.
    steps
        Mean steps of the met runs (``None`` when none met).
    violated, open
        Runs whose system objective was violated / still open at the step budget.
    per_test_met
        Per test (in the order given), the share of its runs that met.
    """

    tests: int
    runs: int
    seed: int
    met: float
    realized: float | None
    restrictions: float
    steps: float | None
    violated: int
    open: int
    per_test_met: tuple[float, ...]

    def to_json(self) -> dict[str, Any]:
        """The fields as a JSON object (``per_test_met`` a list)."""
        d = asdict(self)
        d["per_test_met"] = list(self.per_test_met)
        return d


def summarize(verdicts: dict[str, np.ndarray], seed: int = 0) -> PolicyScore:
    """The :class:`PolicyScore` of verdict arrays of shape ``[runs, n_tests]`` (as
    :func:`play_batch` returns them)."""
    so = np.asarray(verdicts["system_objective"])
    runs, t = so.shape
    met = so == "met"
    n_met = int(met.sum())
    realized = np.asarray(verdicts["test_objective_realized"], dtype=bool)
    return PolicyScore(
        tests=int(t),
        runs=int(runs),
        seed=int(seed),
        met=float(met.mean()),
        realized=float((realized & met).sum() / n_met) if n_met else None,
        restrictions=float(np.mean(verdicts["restrictions"])),
        steps=float(np.asarray(verdicts["steps"])[met].mean()) if n_met else None,
        violated=int((so == "violated").sum()),
        open=int((so == "open").sum()),
        per_test_met=tuple(float(x) for x in met.mean(axis=0)),
    )


def score_policy(
    policy: Callable[[np.ndarray, np.ndarray], Any],
    pool: str | None = None,
    split: str = "test",
    count: int = 1000,
    runs: int = 1,
    seed: int = 0,
    tests: Sequence[Any] | None = None,
    source: PoolSource | None = None,
    obs_kind: str = "flat",
) -> PolicyScore:
    """Score a batched policy (module docstring) on the first ``count`` tests of a pool's
    split, or on ``tests`` (artifacts or games) when given, playing each test ``runs``
    times in one batch (:func:`play_batch`).

    Use ``runs=1`` for a deterministic (greedy) policy and ``runs=K`` (the benchmark uses
    8) for one that samples; the benchmark reports both for its learned baselines.
    ``source`` loads the pool (:data:`PoolSource`; default
    :func:`flowtest_env.pools.load_pool`).

    Example::

        from flowtest_env.scoring import random_policy, score_policy
        floor = score_policy(random_policy(), pool="reachability1/5x5", split="test", count=1000, runs=8)
        print(f"random meets {100 * floor.met:.1f} % of the runs")

    Raises
    ------
    ValueError
        On neither ``pool`` nor ``tests``, a bad pool name, split or count, ``runs < 1``, or
        a policy answering the wrong shape.

    Examples
    --------
    >>> import numpy as np
    >>> from flowtest_env import load_test
    >>> from flowtest_env.scoring import random_policy, score_policy
    >>> tests = [load_test("small-reactive")]
    >>> def first_legal(observations, masks):          # a batched policy: one action per row
    ...     return np.argmax(masks, axis=1)
    >>> greedy = score_policy(first_legal, tests=tests)
    >>> greedy.tests, greedy.runs, len(greedy.per_test_met)
    (1, 1, 1)
    >>> floor = score_policy(random_policy(), tests=tests, runs=8, seed=0)
    >>> floor.runs, 0.0 <= floor.met <= 1.0
    (8, True)
    """
    if tests is None:
        if pool is None:
            raise ValueError("score_policy needs pool= (a pool name) or tests= (a list of tests)")
        games = load_tests(pool, split, count, source)
    else:
        games = [t if isinstance(t, TestGame) else TestGame(t) for t in tests]
    return summarize(play_batch(policy, games, runs, seed, obs_kind), seed)


# --------------------------------------------------------------------------- statistics


def normalized(value: float | None, floor: float | None, ceiling: float | None) -> float | None:
    """``(value - floor) / (ceiling - floor)``: 0 at the floor (random), 1 at the ceiling
    (the reference); ``None`` when a number is missing or the ceiling is not above the floor
    (then no scale exists)."""
    if value is None or floor is None or ceiling is None or not ceiling > floor:
        return None
    return (float(value) - float(floor)) / (float(ceiling) - float(floor))


def iqm(values: Sequence[float] | np.ndarray) -> float:
    """The interquartile mean: the mean of the values left after cutting
    ``floor(0.25 n)`` of the lowest and as many of the highest (the 25 % trimmed mean; for
    fewer than 4 values, the plain mean).

    Raises
    ------
    ValueError
        On no value.
    """
    x = np.sort(np.asarray(values, dtype=np.float64).ravel())
    if x.size == 0:
        raise ValueError("iqm of no value")
    k = int(math.floor(0.25 * x.size))
    return float(x[k : x.size - k].mean())


def worst_share_mean(per_test: Sequence[float] | np.ndarray, share: float = 0.1) -> float:
    """The mean of the worst ``share`` of the per-test scores (at least one test): the
    CVaR-style score on the hardest tests.

    Raises
    ------
    ValueError
        On no test or a share outside (0, 1].
    """
    x = np.sort(np.asarray(per_test, dtype=np.float64).ravel())
    if x.size == 0:
        raise ValueError("no test")
    if not 0 < share <= 1:
        raise ValueError(f"share must be in (0, 1], not {share}")
    k = max(1, int(math.ceil(share * x.size)))
    return float(x[:k].mean())


def seed_iqm(scores: np.ndarray) -> float:
    """The IQM over seeds (rows) of each seed's mean over tests (columns)."""
    return iqm(np.asarray(scores, dtype=np.float64).mean(axis=1))


PRELIMINARY_SEEDS = 5
"""Below this many seeds a score is *preliminary*: the mean over seeds with a Student-t
interval (:func:`score_interval`), not the IQM with a bootstrap interval (an IQM of 3 values
trims nothing, and a bootstrap over 3 seeds resamples 3 values: its interval is about their
range)."""

TAIL_SHARE = 0.1
"""The share of the hardest tests whose mean met rate is the tail score (:func:`tail_score`)."""


def crossed_draws(n_seeds: int, n_tests: int, reps: int, seed: int = 0, resample_seeds: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """The replicates of the seed-and-test bootstrap, ``(seeds, tests)``: ``seeds[r]`` the
    ``n_seeds`` seed indices of replicate ``r`` (drawn with replacement; ``0 .. n-1`` when
    ``resample_seeds`` is false) and ``tests[r, t]`` how often test ``t`` is drawn in replicate
    ``r`` (``n_tests`` draws with replacement). One test draw per replicate is **shared** by every
    seed, by the floor and by the ceiling: every seed plays the same tests (a crossed design), so
    a resample of the tests is one for all of them. Seeded (``numpy.random.default_rng(seed)``:
    the tests are drawn first, then the seeds)."""
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, n_tests, size=(reps, n_tests))
    counts = np.bincount((idx + n_tests * np.arange(reps)[:, None]).ravel(), minlength=reps * n_tests)
    who = rng.integers(0, n_seeds, size=(reps, n_seeds)) if resample_seeds else np.tile(np.arange(n_seeds), (reps, 1))
    return who, counts.reshape(reps, n_tests)


@dataclass(frozen=True)
class ScoreInterval:
    """A score over seeds and tests with its interval (:func:`score_interval`); JSON by
    :meth:`to_json`.

    Attributes
    ----------
    point, low, high
        The score and its interval (normalized: 0 = floor, 1 = ceiling, when a scale was given).
    statistic
        What ``point`` is: ``"iqm"`` (the interquartile mean over seeds of each seed's mean
        over tests; :data:`PRELIMINARY_SEEDS` seeds or more) or ``"mean"`` (fewer).
    interval
        How ``low`` and ``high`` were found: ``"seed-and-test bootstrap"`` (percentile
        interval; seeds and tests resampled, one test resample shared by every seed, the
        floor and the ceiling) or ``"t over seeds and tests"`` (the Student-t interval over
        the seed means, ``n - 1`` degrees of freedom, widened by the tests', the floor's and
        the ceiling's error: the two half-widths added in quadrature).
    preliminary
        Fewer than :data:`PRELIMINARY_SEEDS` seeds.
    mean
        The mean over seeds and tests (whatever ``statistic`` is).
    seeds, tests, confidence
        The matrix's shape and the interval's level.
    seed_se, test_se
        The t interval's parts (``None`` for the bootstrap; ``seed_se`` ``None`` with one seed):
        the standard error of the mean of the seed means, and the standard deviation of the
        normalized mean over the shared test resample with the seeds held.
    """

    point: float
    low: float
    high: float
    statistic: str
    interval: str
    preliminary: bool
    mean: float
    seeds: int
    tests: int
    confidence: float = 0.95
    seed_se: float | None = None
    test_se: float | None = None

    def to_json(self) -> dict[str, Any]:
        """The fields as a JSON object."""
        return asdict(self)


def _matrix(scores: np.ndarray | Sequence[Sequence[float]]) -> np.ndarray:
    x = np.asarray(scores, dtype=np.float64)
    if x.ndim != 2 or x.size == 0:
        raise ValueError(f"scores must be a non-empty [seeds, tests] matrix, not of shape {x.shape}")
    return x


def _per_test(values: Sequence[float] | np.ndarray | None, n_tests: int, what: str) -> np.ndarray | None:
    if values is None:
        return None
    v = np.asarray(values, dtype=np.float64).ravel()
    if v.size != n_tests:
        raise ValueError(f"{what} has {v.size} per-test values for {n_tests} tests")
    return v


def _check_bootstrap(reps: int, confidence: float) -> None:
    if reps < 2 or not 0 < confidence < 1:
        raise ValueError(f"reps must be at least 2 and confidence in (0, 1), not {reps} and {confidence}")


def _iqm_rows(values: np.ndarray) -> np.ndarray:
    """:func:`iqm` of each row."""
    n = values.shape[1]
    k = int(math.floor(0.25 * n))
    out: np.ndarray = np.sort(values, axis=1)[:, k : n - k].mean(axis=1)
    return out


def score_interval(
    scores: np.ndarray | Sequence[Sequence[float]],
    floor: Sequence[float] | np.ndarray | None = None,
    ceiling: Sequence[float] | np.ndarray | None = None,
    reps: int = 2000,
    seed: int = 0,
    confidence: float = 0.95,
) -> ScoreInterval | None:
    """A system's score on a split and its interval, from ``scores`` ``[seeds, tests]`` (each
    seed's met share on each test: 0/1 for a greedy run, ``k / K`` for ``K`` sampled runs),
    normalized by the per-test met shares of the ``floor`` (random's, each from its ``K``
    runs) and of the ``ceiling`` (the reference's) on the **same tests** when given:
    ``(met - floor) / (ceiling - floor)`` of the means. Without them the raw met share.

    * With :data:`PRELIMINARY_SEEDS` seeds or more: the **IQM over seeds** of each seed's
      score, and the **seed-and-test bootstrap** percentile interval: each of ``reps``
      replicates draws the tests with replacement **once** (every seed, the floor and the
      ceiling get that same draw: :func:`crossed_draws`) and the seeds with replacement,
      and recomputes the IQM, the floor and the ceiling. So the interval covers the training
      seeds, the sampling of the tests, and the floor's and ceiling's own sampling error
      (the floor's per-test shares carry its runs' noise; they are not resampled a second
      time within a test, which would count that noise twice: docs/benchmark-protocol.md).
    * With fewer (**preliminary**): the **mean** over seeds and the **Student-t interval over
      the seed means** (``t(n - 1) * s / sqrt(n)``; none for one seed) widened by the error of
      the tests, the floor and the ceiling (``t(tests - 1)`` times the standard deviation of
      the same shared-test bootstrap with the seeds held): the two half-widths added in
      quadrature. It is never narrower than the t interval over the seed means alone, which
      leaves the tests and the floor out; a Welch-Satterthwaite pooling would be narrower
      and undercovers with 2-3 seeds (docs/benchmark-protocol.md).

    ``None`` when the ceiling's mean is not above the floor's (no scale). Seeded: the same
    inputs give the same interval.

    Raises
    ------
    ValueError
        On an empty matrix, a floor or ceiling of another length, ``reps < 2`` or a
        confidence outside (0, 1).

    Examples
    --------
    >>> import numpy as np
    >>> from flowtest_env.scoring import score_interval
    >>> rng = np.random.default_rng(0)
    >>> met = rng.binomial(8, 0.8, size=(10, 200)) / 8         # 10 seeds x 200 tests, 8 sampled runs each
    >>> floor = rng.binomial(8, 0.4, size=200) / 8             # random's per-test met share
    >>> s = score_interval(met, floor, np.ones(200), reps=500)
    >>> s.statistic, s.interval, s.low < s.point < s.high
    ('iqm', 'seed-and-test bootstrap', True)
    >>> score_interval(met[:3], floor, np.ones(200), reps=500).statistic  # 3 seeds: preliminary
    'mean'
    """
    x = _matrix(scores)
    _check_bootstrap(reps, confidence)
    s, t = x.shape
    f = _per_test(floor, t, "the floor")
    c = _per_test(ceiling, t, "the ceiling")
    f0 = float(f.mean()) if f is not None else 0.0
    c0 = float(c.mean()) if c is not None else 1.0
    if not c0 > f0:
        return None
    seed_means = x.mean(axis=1)
    z_seeds = (seed_means - f0) / (c0 - f0)
    mean = float(z_seeds.mean())
    alpha = (1 - confidence) / 2
    preliminary = s < PRELIMINARY_SEEDS
    who, counts = crossed_draws(s, t, reps, seed, resample_seeds=not preliminary)
    w = counts / t
    f_r = w @ f if f is not None else np.zeros(reps)
    c_r = w @ c if c is not None else np.ones(reps)
    span = c_r - f_r
    ok = span > 0  # a replicate without a scale (its ceiling not above its floor) is left out
    if not ok.any():
        return None
    if not preliminary:
        met_r = _iqm_rows(np.take_along_axis(w @ x.T, who, axis=1))
        z = (met_r[ok] - f_r[ok]) / span[ok]
        low, high = np.quantile(z, [alpha, 1 - alpha])
        return ScoreInterval(iqm(z_seeds), float(low), float(high), "iqm", "seed-and-test bootstrap", False, mean, s, t, confidence)
    z = ((w @ x.mean(axis=0))[ok] - f_r[ok]) / span[ok]
    test_se = float(np.std(z, ddof=1)) if z.size > 1 else 0.0
    seed_se = float(np.std(z_seeds, ddof=1) / math.sqrt(s)) if s > 1 else None
    from scipy.stats import t as student

    half_seeds = float(student.ppf(1 - alpha, s - 1)) * seed_se if seed_se is not None else 0.0
    half_tests = float(student.ppf(1 - alpha, max(t - 1, 1))) * test_se
    half = math.hypot(half_seeds, half_tests)
    return ScoreInterval(mean, mean - half, mean + half, "mean", "t over seeds and tests", True, mean, s, t, confidence, seed_se, test_se)


@dataclass(frozen=True)
class TailScore:
    """The mean met share of the hardest ``share`` of the tests (the CVaR at level ``share``
    of the per-test met shares, each test's share averaged over seeds and runs:
    :func:`tail_score`); JSON by :meth:`to_json`. It has no interval: see :func:`tail_score`."""

    share: float
    point: float
    seeds: int
    tests: int

    def to_json(self) -> dict[str, Any]:
        """The fields as a JSON object."""
        return asdict(self)


def tail_score(scores: np.ndarray | Sequence[Sequence[float]], share: float = TAIL_SHARE) -> TailScore:
    """The tail of a system's scores ``[seeds, tests]``: each test's met share averaged over
    the seeds, and the mean of the lowest ``ceil(share * tests)`` of them
    (:func:`worst_share_mean`: the CVaR of the per-test met shares). With sampled runs a
    test's share is not 0 or 1, so the tail ranks policies that all fail some test
    somewhere; of greedy runs it is mostly 0.

    No interval is given: the bootstrap of a tail mean is not trustworthy here. Resampling
    the seeds changes how noisy each test's averaged share is, which moves the tail itself (a
    simulation with 5 seeds covered the true tail in 67 % of the cases at 95 %); resampling the
    tests only leaves the seeds' variation out (81 %); docs/benchmark-protocol.md.

    Raises
    ------
    ValueError
        On an empty matrix or a share outside (0, 1].

    Examples
    --------
    >>> import numpy as np
    >>> from flowtest_env.scoring import tail_score
    >>> met = np.array([[1.0, 0.5, 0.25, 1.0], [1.0, 0.75, 0.25, 1.0]])
    >>> tail_score(met, share=0.25).point          # the hardest test: (0.25 + 0.25) / 2
    0.25
    """
    x = _matrix(scores)
    return TailScore(share, worst_share_mean(x.mean(axis=0), share), int(x.shape[0]), int(x.shape[1]))
