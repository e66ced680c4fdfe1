"""A masked PPO written for FlowTest's batched env, no RL framework (torch only): the loop
(:func:`train`), read top to bottom, over the pieces of :mod:`agents.native`, split as
CleanRL splits its variants:

* :mod:`agents.native.args`: :class:`NativeArgs` (one line per setting), :func:`check_args`;
* :mod:`agents.native.envs`: the vector env (:func:`~agents.native.envs.make_vec_env`) and
  the visited-places memory;
* :mod:`agents.native.agent`: the network contract (:class:`Agent`) and the masks
  (:func:`masked_logits`); :mod:`agents.native.mlp` the MLP, :mod:`agents.native.gru` the
  GRU, :mod:`agents.native.networks` the one a setting names;
* :mod:`agents.native.core`: the PPO core every network shares: the rollout
  (:func:`collect_rollout`), the advantages (:func:`advantages`), the update
  (:func:`ppo_update`);
* :mod:`agents.native.plr`: prioritized level replay (:class:`LevelSampler`);
* :mod:`agents.native.evaluation`: greedy evaluation (:func:`batch_verdicts`) and batched
  play (:class:`BatchActor`);
* :mod:`agents.native.logs`: ``progress.csv`` and TensorBoard;
* :mod:`agents.native.checkpoint`: the checkpoint written and read back
  (:func:`save_policy`, :func:`load_native`).

::

    from agents.native_ppo import NativeArgs, train
    result = train(NativeArgs(env_id="FlowTest-RandomGrid-v0",
                              env_kwargs={"pool": "reachability1/5x5", "split": "train", "count": 128},
                              total_steps=2_000_000), out="policy.zip")
    # then: flowtest evaluate --env ... --sut ppo:policy.zip

What it gets right, and where:

* **Masks**: the logits of illegal actions are set to ``-1e8`` (minus infinity in effect:
  their probability is exactly 0 in float32, and the entropy stays finite), so the policy
  never samples a restricted move (:func:`masked_logits`).
* **The autoreset step**: the vector env resets an env on the step *after* its episode
  ended (Gymnasium's ``NEXT_STEP``), ignoring that step's action. Such a step is no
  transition of the policy: :class:`Rollout` marks it (``valid`` is false) and the loss
  never trains on it (:func:`ppo_update` draws its samples from the valid steps only).
* **Truncation vs termination**: a terminated episode bootstraps nothing; a truncated one
  (its step budget ran out) bootstraps the value of its last observation, which the
  ``NEXT_STEP`` env returns at the truncating step (:func:`advantages`).
* **Memory**: ``memory="visited"`` appends the places the SUT has occupied this episode
  (read from its own position in the observations it saw, as
  :class:`flowtest_env.wrappers.VisitedPlaces`); the GRU variant carries its hidden
  state, reset at each episode's first observation.
* **Deterministic on the CPU**: one seed fixes the env draws, the network and every
  sample (torch's generator, a fixed thread count).

The saved file is a native checkpoint (:mod:`agents.checkpoint`: tensors and plain
settings, never unpickled) that loads as the ``ppo:PATH`` system under test.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from flowtest_env.encoding import make_encoder
from flowtest_env.wrappers import shared_position_slice

from .native.agent import Agent, masked_logits
from .native.args import ALGOS, NativeArgs, check_args, resolve_device
from .native.checkpoint import NativeModel, checkpoint_settings, load_native, save_policy
from .native.core import Rollout, Runner, advantages, collect_rollout, minibatch_indices, ppo_update
from .native.envs import make_vec_env
from .native.evaluation import BatchActor, batch_verdicts, met_rate
from .native.inputs import varying_columns, widen
from .native.logs import Logs
from .native.networks import make_agent, network_settings
from .native.optim import FlatAdam
from .native.plr import LevelSampler, level_sampler


@dataclass
class TrainResult:
    """What a run did: its settings, the steps taken, training seconds (evaluations
    excluded), steps per second, the greedy evaluations (``[(step, {split: rates})]``,
    with the training seconds of each in ``eval_times``) and the final ones, and the
    checkpoint's path (``None`` if not saved). With validation tests, ``agent`` (and the
    checkpoint) is the network of the evaluation with the best validation score, at step
    ``selected_step``; otherwise the last one."""

    args: NativeArgs
    steps: int
    seconds: float
    eval_seconds: float
    evaluations: list[tuple[int, dict[str, dict[str, float]]]]
    final: dict[str, dict[str, float]]
    path: Path | None
    agent: Agent
    settings: dict[str, Any]
    rows: list[dict[str, Any]] = field(default_factory=list)
    eval_times: list[float] = field(default_factory=list)  # training seconds (evaluations excluded) at each evaluation
    selected_step: int | None = None  # the step of the network kept (validation selection), None: the last

    @property
    def steps_per_second(self) -> float:
        return self.steps / self.seconds if self.seconds > 0 else 0.0


def _budgets(games: Sequence[Any]) -> list[int]:
    from flowtest_env.envs import default_max_steps

    return [default_max_steps(g) for g in games]


def input_columns(args: NativeArgs, env: Any, games: Sequence[Any], memory: int, device: torch.device) -> torch.Tensor | None:
    """The observation entries the network trains on (:mod:`agents.native.inputs`): with
    ``inputs="varying"``, those that vary over the observation table of the env's tests
    (a :class:`~flowtest_env.vector.PoolVectorEnv`'s ``pool.obs``) and the ``memory``
    entries; ``None`` (all) otherwise, for an env without such a table, or in the
    accumulative setting (its observations add the restrictions of visited states to the
    table's rows)."""
    table = getattr(getattr(env, "pool", None), "obs", None)
    if args.inputs != "varying" or table is None or any(getattr(g, "setting", None) == "accumulative" for g in games):
        return None
    t = np.asarray(table)
    cols = varying_columns(t.reshape(t.shape[0], -1), memory)
    return None if cols is None else torch.as_tensor(cols, device=device)


def train(
    args: NativeArgs,
    out: str | Path | None = None,
    heldout: Sequence[Any] = (),
    log_dir: str | Path | None = None,
    progress_bar: bool = True,
    evaluate_train: bool | int = True,
    env: Any = None,
    validation: Sequence[Any] = (),
    until: Callable[[int, dict[str, dict[str, float]]], bool] | None = None,
) -> TrainResult:
    """Train a masked PPO agent (see the module docstring), evaluating it greedily on the
    env's own tests (the train tests; with ``evaluate_train=N`` the first ``N`` of them), on
    ``heldout`` games and on ``validation`` games every ``args.eval_every`` steps and at the
    end; save the checkpoint to ``out`` (atomically) when given.

    **Checkpoint selection.** With ``validation`` games (a pool's ``validation`` split,
    never trained on), the network kept, returned and saved is the one of the evaluation
    with the best greedy validation met (the latest of equals), not the last: the curve is
    in the log (``eval/validation_met``), the step kept in ``selected_step`` and in the
    checkpoint's settings (``selected``). Without them, the last network.

    **Stopping early.** ``until(step, rates)``, called after each evaluation with its
    rates (``{split: {"met": ...}}``), ends the run when it returns true (e.g. once the
    train tests are met: ``until=lambda step, r: r["train"]["met"] >= 0.95``); the
    learning rate still anneals over ``args.total_steps``.

    Raises
    ------
    ValueError
        On settings no run can use (:func:`check_args`) or an env it cannot train on.

    Examples
    --------
    A tiny budget on one built-in (a real run: docs/training.md):

    >>> from agents.native_ppo import NativeArgs, train
    >>> args = NativeArgs(env_id="FlowTest-SmallReactive-v0", num_envs=8, num_steps=8, total_steps=128,
    ...                   hidden=(16,), device="cpu", eval_every=0)
    >>> result = train(args, progress_bar=False)
    >>> result.steps, sorted(result.final["train"])
    (128, ['met', 'realized', 'restrictions'])
    """
    check_args(args)
    device = resolve_device(args.device)
    torch.set_num_threads(int(args.threads))
    torch.manual_seed(args.seed)
    np.random.seed(args.seed)
    np_env, env, env_memory = make_vec_env(args) if env is None else (env, env, False)
    inner = np_env.unwrapped
    games = list(getattr(inner, "games", []))
    n_actions = int(env.single_action_space.n)
    where = shared_position_slice([make_encoder(g, args.obs_kind) for g in games]) if args.memory != "none" else None
    mem_size = where.stop - where.start if where is not None else 0
    obs_size = int(np.prod(env.single_observation_space.shape)) - (mem_size if env_memory else 0)  # without memory
    net = network_settings(args)
    full_size = obs_size + mem_size
    columns = input_columns(args, inner, games, mem_size, device)
    agent = make_agent(full_size if columns is None else int(columns.numel()), n_actions, net["hidden"], net["kind"], net["gru_hidden"]).to(device)

    def whole() -> Agent:  # the network on the whole observation (inputs.widen), the global RNG untouched
        if columns is None:
            return agent
        with torch.random.fork_rng(devices=[]):
            return widen(agent, columns, full_size)

    optimizer = FlatAdam(agent.flat_order(), lr=args.learning_rate, eps=1e-5)
    generator = torch.Generator().manual_seed(args.seed)
    sampler = level_sampler(args, inner, len(games))
    runner = Runner(
        env,
        agent,
        None if env_memory else where,
        device,
        args.seed,
        levels=(lambda: np.asarray(inner.test_index)) if sampler is not None else None,
        memory=args.memory,
        columns=columns,
    )
    shown = games if evaluate_train is True else games[: int(evaluate_train)]
    splits = {"train": (shown, _budgets(shown))} if evaluate_train and games else {}
    if heldout:
        splits["heldout"] = (list(heldout), _budgets(heldout))
    if validation:
        splits["validation"] = (list(validation), _budgets(validation))
    best: tuple[float, int, dict[str, torch.Tensor]] | None = None  # validation met, step, the network's tensors
    logs = Logs(log_dir, quiet=not progress_bar)
    total = math.ceil(args.total_steps / args.num_envs) * args.num_envs  # whole steps of every env
    evaluations: list[tuple[int, dict[str, dict[str, float]]]] = []
    eval_seconds = 0.0
    eval_times: list[float] = []
    next_eval = 0

    def evaluate(step: int) -> dict[str, dict[str, float]]:
        nonlocal eval_seconds, best
        t = time.perf_counter()
        eval_times.append(t - t0 - eval_seconds)
        playing = whole()
        rates = {name: met_rate(playing, g, b, where, args.obs_kind, device, args.memory) for name, (g, b) in splits.items()}
        if "validation" in rates and (best is None or rates["validation"]["met"] >= best[0]):
            best = (rates["validation"]["met"], step, {k: v.detach().clone() for k, v in agent.state_dict().items()})
        eval_seconds += time.perf_counter() - t
        evaluations.append((step, rates))
        logs.add(step, {"train/seconds": eval_times[-1], **{f"eval/{name}_{k}": v for name, r in rates.items() for k, v in r.items()}})
        return rates

    bar = None
    if progress_bar:
        from tqdm import tqdm

        bar = tqdm(total=total, unit="step", desc="training", file=sys.stderr, mininterval=1.0, unit_scale=True)
    t0 = time.perf_counter()
    step = 0
    stopped: dict[str, dict[str, float]] | None = None  # the evaluation that ended the run early
    try:
        while step < total:
            if splits and args.eval_every and step >= next_eval:
                rates = evaluate(step)
                while next_eval <= step:
                    next_eval += args.eval_every
                if until is not None and until(step, rates):
                    stopped = rates
                    break
            if args.anneal_lr:
                optimizer.param_groups[0]["lr"] = args.learning_rate * (1.0 - step / total)
            num_steps = min(args.num_steps, (total - step) // args.num_envs)  # the last rollout may be shorter
            rollout = collect_rollout(runner, num_steps)
            if sampler is not None and rollout.levels is not None:
                adv, _ = advantages(rollout, args.gamma, args.gae_lambda)
                sampler.update(rollout.levels, adv.cpu().numpy(), rollout.valid.cpu().numpy(), rollout.starts.cpu().numpy())
                info_plr = {f"plr/{k}": v for k, v in sampler.stats().items()}
            else:
                info_plr = {}
            info = ppo_update(agent, optimizer, args, rollout, generator)
            step += num_steps * args.num_envs
            episode = runner.stats.take()
            elapsed = time.perf_counter() - t0 - eval_seconds
            logs.add(
                step,
                {
                    "train/steps_per_second": step / max(elapsed, 1e-9),
                    "train/lr": optimizer.param_groups[0]["lr"],
                    **{f"episode/{k}": v for k, v in episode.items()},
                    **{f"loss/{k}": v for k, v in info.items()},
                    **info_plr,
                },
            )
            if bar is not None:
                bar.update(num_steps * args.num_envs)
                if "met" in episode:
                    bar.set_postfix(met=f"{100 * episode['met']:.0f}%", refresh=False)
        seconds = time.perf_counter() - t0 - eval_seconds
        final = stopped if stopped is not None else evaluate(step) if splits else {}
    except BaseException:
        logs.close(wait=False)  # Ctrl-C ends the run now (Logs.close)
        raise
    finally:
        if bar is not None:
            bar.close()
    logs.close()
    settings = checkpoint_settings(args, inner, obs_size, n_actions, where, step)
    settings["trained_on"] = str(device)
    selected = None
    if best is not None:
        agent.load_state_dict(best[2])
        selected = best[1]
        settings["selected"] = {"by": "greedy met on the validation tests", "step": best[1], "validation_met": best[0], "validation_tests": len(validation)}
    agent = whole()
    path = None
    if out is not None:
        path = Path(out)
        save_policy(path, agent, settings)
    return TrainResult(args, step, seconds, eval_seconds, evaluations, final, path, agent, settings, logs.rows, eval_times, selected)


__all__ = [
    "ALGOS",
    "NativeArgs",
    "Agent",
    "BatchActor",
    "LevelSampler",
    "Rollout",
    "Runner",
    "TrainResult",
    "NativeModel",
    "advantages",
    "batch_verdicts",
    "check_args",
    "collect_rollout",
    "load_native",
    "make_agent",
    "masked_logits",
    "minibatch_indices",
    "ppo_update",
    "resolve_device",
    "save_policy",
    "train",
]
