"""A masked PPO written for FlowTest's batched env: one module, no RL framework (torch only).

In the CleanRL spirit: :class:`NativeArgs` (one line per setting), the network
(:class:`Agent`: an MLP, or a GRU for the recurrent variant), the rollout
(:func:`collect_rollout`), the advantages (:func:`advantages`), the update
(:func:`ppo_update`) and the loop (:func:`train`)::

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

import csv
import io
import math
import os
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from flowtest_env.compiled import OUTCOMES

from .checkpoint import Checkpoint, CheckpointError, load_checkpoint, save_checkpoint

ALGOS = ("ppo", "recurrent-ppo")
"""The native algorithms: masked PPO with an MLP, and with a GRU."""

LEVEL_SAMPLING = ("uniform", "plr")
"""How each episode's test is chosen: the env's own uniform draws, or prioritized level
replay (:class:`LevelSampler`)."""

PLR_SCORES = ("pvl", "gae")
"""PLR's level scores: positive value loss (the mean of the positive GAE advantages of the
level's last run) or the mean GAE magnitude."""

ENV_BACKENDS = ("auto", "torch", "numpy")
"""Who steps the tests: the NumPy vector env, or its torch twin on the training device
(``auto``: the torch env: alone it steps slower than the NumPy env on the CPU, but the two
train at the same rate within noise there, it spares the NumPy/torch conversions, and on a
GPU it keeps the tests on the device; both give the same runs)."""


@dataclass
class NativeArgs:
    """Every setting of a native training run (saved in the checkpoint and the summary)."""

    env_id: str = "FlowTest-RandomGrid-v0"  # a FlowTest ID with a vector entry point
    env_kwargs: dict[str, Any] = field(default_factory=dict)  # its options (pool, split, count, test, ...)
    algo: str = "ppo"  # "ppo" (MLP) or "recurrent-ppo" (GRU)
    total_steps: int = 2_000_000  # env steps of all envs together (rounded up to a multiple of num_envs)
    num_envs: int = 128  # envs stepped together
    num_steps: int = 32  # rollout length per env
    num_minibatches: int = 4  # minibatches per epoch
    update_epochs: int = 2  # passes over each rollout
    learning_rate: float = 1e-3  # Adam's step size (annealed linearly to 0 when anneal_lr)
    anneal_lr: bool = True  # anneal the learning rate
    gamma: float = 0.99  # discount
    gae_lambda: float = 0.95  # GAE's lambda
    clip_coef: float = 0.2  # PPO's ratio clip
    ent_coef: float = 0.01  # entropy bonus
    vf_coef: float = 0.5  # value loss weight
    max_grad_norm: float = 0.5  # gradient clip
    hidden: tuple[int, ...] = (256, 256)  # MLP widths (the GRU variant: its input layers)
    gru_hidden: int = 128  # GRU width (recurrent-ppo)
    memory: str = "visited"  # "visited" (places occupied this episode) or "none"
    obs_kind: str = "flat"  # the env's observation: "flat" or "padded"
    shaping: float = 0.0  # env option: potential-based shaping scale (0 = off)
    env_backend: str = "auto"  # "torch" (flowtest_env.torch_vector, on the device), "numpy" (flowtest_env.vector); "auto": numpy on the CPU, else torch
    seed: int = 0  # seeds the envs, the network and every sample
    device: str = "auto"  # "auto" (cuda when there is one), "cpu", "cuda", "cuda:1", ...
    threads: int = 1  # torch CPU threads (fixed, so a seed gives the same run)
    eval_every: int = 250_000  # steps between greedy evaluations on the train (and held-out) tests; 0: at the end only
    level_sampling: str = "uniform"  # "uniform" (the env's own draws) or "plr" (prioritized level replay over the train tests)
    plr_score: str = "pvl"  # PLR's level score: "pvl" (positive value loss) or "gae" (mean GAE magnitude)
    plr_temperature: float = 0.1  # PLR's rank temperature (beta)
    plr_staleness: float = 0.1  # PLR's staleness weight (rho)

    def batch_size(self) -> int:
        """Steps per rollout (all envs)."""
        return self.num_envs * self.num_steps


def check_args(a: NativeArgs) -> None:
    """Refuse settings no run can use.

    Raises
    ------
    ValueError
        Naming the setting and the range it must be in.
    """
    if a.algo not in ALGOS:
        raise ValueError(f"unknown algo {a.algo!r}; expected one of {', '.join(ALGOS)}")
    for name in ("total_steps", "num_envs", "num_steps", "num_minibatches", "update_epochs", "gru_hidden", "threads"):
        if int(getattr(a, name)) < 1:
            raise ValueError(f"{name} must be at least 1, not {getattr(a, name)}")
    if a.algo == "recurrent-ppo" and a.num_envs % a.num_minibatches:
        raise ValueError(f"recurrent-ppo splits envs into minibatches: num_envs {a.num_envs} must be a multiple of "
                         f"num_minibatches {a.num_minibatches}")
    if a.algo == "ppo" and a.batch_size() < a.num_minibatches:
        raise ValueError("num_envs x num_steps must be at least num_minibatches")
    for name in ("learning_rate", "clip_coef", "max_grad_norm"):
        if not float(getattr(a, name)) > 0:
            raise ValueError(f"{name} must be positive, not {getattr(a, name)}")
    for name in ("gamma", "gae_lambda"):
        if not 0 < float(getattr(a, name)) <= 1:
            raise ValueError(f"{name} must be in (0, 1], not {getattr(a, name)}")
    for name in ("ent_coef", "vf_coef", "shaping", "eval_every"):
        if float(getattr(a, name)) < 0:
            raise ValueError(f"{name} must not be negative, not {getattr(a, name)}")
    if not a.hidden or any(int(w) < 1 for w in a.hidden):
        raise ValueError(f"hidden must be positive layer widths, not {a.hidden}")
    if a.memory not in ("none", "visited"):
        raise ValueError(f"unknown memory {a.memory!r}; expected 'none' or 'visited'")
    if a.env_backend not in ENV_BACKENDS:
        raise ValueError(f"unknown env_backend {a.env_backend!r}; expected one of {', '.join(ENV_BACKENDS)}")
    if a.obs_kind not in ("flat", "padded"):
        raise ValueError(f"obs_kind must be 'flat' or 'padded' for the native trainer, not {a.obs_kind!r}")
    if a.level_sampling not in LEVEL_SAMPLING:
        raise ValueError(f"unknown level_sampling {a.level_sampling!r}; expected one of {', '.join(LEVEL_SAMPLING)}")
    if a.plr_score not in PLR_SCORES:
        raise ValueError(f"unknown plr_score {a.plr_score!r}; expected one of {', '.join(PLR_SCORES)}")
    if not float(a.plr_temperature) > 0 or not 0 <= float(a.plr_staleness) <= 1:
        raise ValueError("plr_temperature must be positive and plr_staleness in [0, 1]")
    if a.level_sampling == "plr" and a.env_backend == "torch":
        raise ValueError("level_sampling 'plr' chooses each episode's test in the NumPy env: use env_backend 'numpy' or 'auto'")
    resolve_device(a.device)


def resolve_device(name: str) -> torch.device:
    """``"auto"``: the first CUDA device when torch sees one, else the CPU.

    Raises
    ------
    ValueError
        For a device name torch does not know, or CUDA asked for where there is none.
    """
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        dev = torch.device(name)
    except (RuntimeError, TypeError) as exc:
        raise ValueError(f"unknown device {name!r}: {exc}") from None
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"device {name!r}: torch sees no CUDA device here (use --device cpu or auto)")
    if dev.type not in ("cpu", "cuda"):
        raise ValueError(f"device {name!r}: expected cpu, cuda or auto")
    return dev


# --------------------------------------------------------------------------- the network


def _layer(n_in: int, n_out: int, std: float) -> nn.Linear:
    layer = nn.Linear(n_in, n_out)
    nn.init.orthogonal_(layer.weight, std)
    nn.init.constant_(layer.bias, 0.0)
    return layer


def _mlp(n_in: int, widths: Sequence[int], n_out: int, out_std: float) -> nn.Sequential:
    layers: list[nn.Module] = []
    for w in widths:
        layers += [_layer(n_in, int(w), math.sqrt(2)), nn.Tanh()]
        n_in = int(w)
    layers.append(_layer(n_in, n_out, out_std))
    return nn.Sequential(*layers)


MET_CODE = OUTCOMES.index("met")
"""The outcome code of ``"met"`` in the torch env's verdicts."""

MASKED_LOGIT = -1e8
"""The logit of an illegal action (its probability is exactly 0 in float32)."""


def masked_logits(logits: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """``logits`` with the illegal actions (``mask`` false) at :data:`MASKED_LOGIT`. A row
    with no legal action (a terminal state, seen only on the autoreset step, whose
    action the env ignores) keeps its logits so the distribution stays defined."""
    legal = mask | ~mask.any(dim=-1, keepdim=True)
    return torch.where(legal, logits, torch.full_like(logits, MASKED_LOGIT))


class Agent(nn.Module):
    """The policy and value networks.

    ``kind="mlp"``: separate actor and critic MLPs of ``hidden`` widths (tanh), as
    stable-baselines3's ``net_arch`` builds them. ``kind="gru"``: a shared input MLP of
    ``hidden`` widths, a GRU cell of ``gru_hidden`` units whose state is zeroed at each
    episode's first observation, and linear actor and critic heads.
    """

    def __init__(self, obs_size: int, n_actions: int, hidden: Sequence[int], kind: str = "mlp", gru_hidden: int = 128) -> None:
        super().__init__()
        self.kind = kind
        self.obs_size, self.n_actions = int(obs_size), int(n_actions)
        self.gru_hidden = int(gru_hidden) if kind == "gru" else 0
        if kind == "mlp":
            self.actor = _mlp(obs_size, hidden, n_actions, 0.01)
            self.critic = _mlp(obs_size, hidden, 1, 1.0)
        elif kind == "gru":
            layers: list[nn.Module] = []
            n_in = obs_size
            for w in hidden:
                layers += [_layer(n_in, int(w), math.sqrt(2)), nn.Tanh()]
                n_in = int(w)
            self.encoder = nn.Sequential(*layers)
            self.gru = nn.GRUCell(n_in, self.gru_hidden)
            self.actor_head = _layer(self.gru_hidden, n_actions, 0.01)
            self.critic_head = _layer(self.gru_hidden, 1, 1.0)
        else:
            raise ValueError(f"unknown network kind {kind!r}")

    def initial_state(self, n: int, device: torch.device) -> torch.Tensor:
        """The hidden state of ``n`` envs before anything was seen (``[n, 0]`` for the MLP)."""
        return torch.zeros(n, self.gru_hidden, device=device)

    def step(self, x: torch.Tensor, h: torch.Tensor, start: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Logits, values and the next hidden state for one observation per env
        (``start``: the observation is its episode's first, so the GRU state is zeroed)."""
        if self.kind == "mlp":
            return self.actor(x), self.critic(x).squeeze(-1), h
        h = h * (~start).to(h.dtype).unsqueeze(-1)
        h = self.gru(self.encoder(x), h)
        return self.actor_head(h), self.critic_head(h).squeeze(-1), h

    def value(self, x: torch.Tensor, h: torch.Tensor, start: torch.Tensor) -> torch.Tensor:
        """The values of one observation per env."""
        if self.kind == "mlp":
            v: torch.Tensor = self.critic(x).squeeze(-1)
            return v
        return self.step(x, h, start)[1]


def network_settings(args: NativeArgs) -> dict[str, Any]:
    """What rebuilds the network: its kind and widths."""
    return {"kind": "gru" if args.algo == "recurrent-ppo" else "mlp", "hidden": [int(w) for w in args.hidden],
            "gru_hidden": int(args.gru_hidden)}


# --------------------------------------------------------------------------- the env and its memory


def make_vec_env(args: NativeArgs) -> tuple[Any, Any, bool]:
    """``args.num_envs`` runs of ``args.env_id`` with the env options of ``args``: the
    NumPy vector env (``vectorization_mode="vector_entry_point"``), and the env to step
    (that one, or with ``env_backend="torch"`` its torch twin on the training device);
    and whether the env itself appends the visited-places memory (``memory="visited"``).

    Raises
    ------
    ValueError
        If the env cannot be made with these options.
    """
    import gymnasium as gym

    import flowtest_env  # noqa: F401 - registers the IDs

    kwargs = dict(args.env_kwargs)
    if args.obs_kind != "flat":
        kwargs["obs_kind"] = args.obs_kind
    if args.shaping > 0:
        kwargs["shaping"], kwargs["shaping_gamma"] = float(args.shaping), float(args.gamma)
    env_memory = args.memory == "visited"
    with_memory: dict[str, Any] = {**kwargs, "memory": "visited"} if env_memory else kwargs
    try:
        try:
            np_env = gym.make_vec(args.env_id, num_envs=args.num_envs, vectorization_mode="vector_entry_point",
                                  **with_memory)
        except TypeError:  # a vector env without the memory option: the trainer keeps it
            env_memory = False
            np_env = gym.make_vec(args.env_id, num_envs=args.num_envs, vectorization_mode="vector_entry_point", **kwargs)
    except TypeError as exc:
        raise ValueError(f"{args.env_id}: the vector env does not take these options ({exc})") from None
    device = resolve_device(args.device)
    from flowtest_env.torch_vector import TorchVectorEnv, preferred_backend

    if args.env_backend == "torch" or (args.env_backend == "auto" and args.level_sampling != "plr" and preferred_backend(device) == "torch"):
        return np_env, TorchVectorEnv.from_numpy(np_env, device=device), env_memory
    return np_env, np_env, env_memory


def shared_position_slice(games: Sequence[Any], obs_kind: str) -> slice:
    """Where every test's observation holds the SUT's place (the visited memory reads it).

    Raises
    ------
    ValueError
        If the tests disagree (then no one memory fits them all).
    """
    from flowtest_env.encoding import make_encoder
    from flowtest_env.wrappers import position_slice

    slices = {(s.start, s.stop) for s in (position_slice(make_encoder(g, obs_kind)) for g in games)}
    if len(slices) != 1:
        raise ValueError("the tests do not share the place of the system in the observation (use obs_kind='padded')")
    start, stop = slices.pop()
    return slice(start, stop)


class VisitedBits:
    """The visited-places memory of a batch: ``seen |= obs[where]``, restarted from the
    observation itself at each episode's first observation (``start``)."""

    def __init__(self, where: slice | None) -> None:
        self.where = where
        self.seen: torch.Tensor | None = None

    def __call__(self, obs: torch.Tensor, start: torch.Tensor) -> torch.Tensor:
        if self.where is None:
            return obs
        here = obs[:, self.where]
        if self.seen is None:
            self.seen = here.clone()
        else:
            self.seen = torch.where(start.unsqueeze(-1), here, torch.maximum(self.seen, here))
        return torch.cat([obs, self.seen], dim=1)


# --------------------------------------------------------------------------- rollout and advantages


@dataclass
class Rollout:
    """``num_steps`` steps of every env (time first: ``[T, N, ...]``).

    ``valid[t, i]`` is false on env ``i``'s autoreset step (its previous step ended an
    episode: the env reset it and ignored the action); the loss never uses those steps.
    ``starts[t, i]``: ``obs[t, i]`` is the first observation of an episode.
    """

    obs: torch.Tensor
    masks: torch.Tensor
    actions: torch.Tensor
    logprobs: torch.Tensor
    values: torch.Tensor
    rewards: torch.Tensor
    terminated: torch.Tensor
    truncated: torch.Tensor
    valid: torch.Tensor
    starts: torch.Tensor
    h0: torch.Tensor
    next_value: torch.Tensor
    levels: np.ndarray | None = None  # int64[T, N]: the test each obs[t, i] belongs to (level sampling only)


class EpisodeStats:
    """Episode ends seen while training: return, met, realized, restrictions, steps."""

    def __init__(self) -> None:
        self.rows: list[tuple[float, bool, bool, int, int]] = []

    def take(self) -> dict[str, float]:
        """Means over the episodes since the last call (empty: ``{}``)."""
        rows, self.rows = self.rows, []
        if not rows:
            return {}
        r = np.array(rows, dtype=np.float64)
        return {"episodes": float(len(rows)), "return": float(r[:, 0].mean()), "met": float(r[:, 1].mean()),
                "realized": float(r[:, 2].mean()), "restrictions": float(r[:, 3].mean()), "length": float(r[:, 4].mean())}


class Runner:
    """Steps the vector env with the agent and keeps what carries over between rollouts:
    the last observation, masks, episode flags, the memory, the GRU state, returns."""

    def __init__(self, env: Any, agent: Agent, where: slice | None, device: torch.device, seed: int,
                 levels: Callable[[], np.ndarray] | None = None) -> None:
        self.env, self.agent, self.device = env, agent, device
        self.levels = levels  # the test each env plays now (recorded per step when given)
        self.n = int(env.num_envs)
        self.torch_env = hasattr(env, "tables")  # flowtest_env.torch_vector: tensors in, tensors out
        obs, infos = env.reset(seed=seed)
        self.memory = VisitedBits(where)
        self.start = torch.ones(self.n, dtype=torch.bool, device=device)
        self.reset_step = torch.zeros(self.n, dtype=torch.bool, device=device)  # the next step is the autoreset step
        self.x = self.memory(self._tensor(obs), self.start)
        self.mask = self._tensor(infos["action_mask"]).bool()
        self.h = agent.initial_state(self.n, device)
        self.ret = torch.zeros(self.n, dtype=torch.float64, device=device)
        self.stats = EpisodeStats()

    def _tensor(self, a: Any) -> torch.Tensor:
        return torch.as_tensor(a if isinstance(a, torch.Tensor) else np.asarray(a), device=self.device)

    def collect(self, num_steps: int) -> Rollout:
        """:func:`collect_rollout`."""
        T, N, dev = num_steps, self.n, self.device
        obs = torch.zeros((T, N, self.x.shape[1]), device=dev)
        masks = torch.zeros((T, N, self.mask.shape[1]), dtype=torch.bool, device=dev)
        actions = torch.zeros((T, N), dtype=torch.long, device=dev)
        logprobs, values, rewards = (torch.zeros((T, N), device=dev) for _ in range(3))
        terminated, truncated, valid, starts = (torch.zeros((T, N), dtype=torch.bool, device=dev) for _ in range(4))
        h0 = self.h.clone()
        levels = np.zeros((T, N), dtype=np.int64) if self.levels is not None else None
        for t in range(T):
            obs[t], masks[t], starts[t], valid[t] = self.x, self.mask, self.start, ~self.reset_step
            if levels is not None and self.levels is not None:
                levels[t] = self.levels()
            with torch.no_grad():
                logits, value, self.h = self.agent.step(self.x, self.h, self.start)
                logits = masked_logits(logits, self.mask)
                a = sample(logits)
                logprobs[t] = torch.log_softmax(logits, dim=-1).gather(1, a.unsqueeze(1)).squeeze(1)
            actions[t], values[t] = a, value
            o, r, term, trunc, infos = self.env.step(a if self.torch_env else a.cpu().numpy())
            rewards[t] = self._tensor(r).float()
            terminated[t], truncated[t] = self._tensor(term), self._tensor(trunc)
            done = terminated[t] | truncated[t]
            self._episode_ends(rewards[t], done, infos)
            self.start = self.reset_step  # the autoreset step's observation is a new episode's first
            self.reset_step = done
            self.x = self.memory(self._tensor(o), self.start)
            self.mask = self._tensor(infos["action_mask"]).bool()
        with torch.no_grad():
            next_value = self.agent.value(self.x, self.h, self.start)
        return Rollout(obs, masks, actions, logprobs, values, rewards, terminated, truncated, valid, starts, h0, next_value,
                       levels)

    def _episode_ends(self, r: torch.Tensor, done: torch.Tensor, infos: dict[str, Any]) -> None:
        self.ret += r
        if not bool(done.any()):
            return
        v = infos["verdict"]
        idx = torch.nonzero(done).squeeze(1)
        outcome = v["system_objective"]
        met = (outcome == MET_CODE) if isinstance(outcome, torch.Tensor) else torch.as_tensor(np.asarray(outcome == "met"))
        cols = [self.ret[idx].cpu().numpy(), met.to(self.device)[idx].cpu().numpy()]
        cols += [self._tensor(v[k])[idx].cpu().numpy() for k in ("test_objective_realized", "restrictions", "steps")]
        for ret, m, real, restr, steps in zip(*cols, strict=True):
            self.stats.rows.append((float(ret), bool(m), bool(real), int(restr), int(steps)))
        self.ret[idx] = 0.0


def sample(logits: torch.Tensor) -> torch.Tensor:
    """One action per row from ``softmax(logits)`` (Gumbel-max, torch's seeded generator)."""
    u = torch.rand_like(logits).clamp_(1e-12, 1.0)
    return torch.argmax(logits - torch.log(-torch.log(u)), dim=-1)


def collect_rollout(runner: Runner, num_steps: int) -> Rollout:
    """``num_steps`` steps of every env of ``runner`` with actions sampled from the masked
    policy (see :class:`Rollout` for what is recorded)."""
    return runner.collect(num_steps)


def advantages(r: Rollout, gamma: float, lam: float) -> tuple[torch.Tensor, torch.Tensor]:
    """GAE advantages and returns of a rollout.

    ``delta_t = r_t + gamma * V(o_{t+1}) * (1 - terminated_t) - V(o_t)``, and the sum
    ``A_t = delta_t + gamma * lam * (1 - done_t) * A_{t+1}`` stops at every episode end.
    At a truncation ``o_{t+1}`` is the episode's last observation (the ``NEXT_STEP``
    env returns it, and resets at the next, invalid step), so its value is bootstrapped;
    at a termination nothing is. The autoreset steps get numbers too but are never used.
    """
    T = r.rewards.shape[0]
    adv = torch.zeros_like(r.rewards)
    last = torch.zeros_like(r.next_value)
    for t in reversed(range(T)):
        next_v = r.next_value if t == T - 1 else r.values[t + 1]
        term = r.terminated[t].float()
        cont = 1.0 - (r.terminated[t] | r.truncated[t]).float()
        delta = r.rewards[t] + gamma * next_v * (1.0 - term) - r.values[t]
        last = delta + gamma * lam * cont * last
        adv[t] = last
    return adv, adv + r.values


def minibatch_indices(valid: torch.Tensor, num_minibatches: int, generator: torch.Generator | None = None) -> list[torch.Tensor]:
    """The flat indices (into ``[T * N]``) of the steps the MLP's loss trains on, in
    ``num_minibatches`` shuffled minibatches: exactly the valid steps, each once."""
    idx = torch.nonzero(valid.reshape(-1), as_tuple=False).squeeze(1)
    perm = idx[torch.randperm(idx.numel(), generator=generator, device="cpu").to(idx.device)]
    return [chunk for chunk in torch.tensor_split(perm, num_minibatches) if chunk.numel()]


def ppo_loss(agent: Agent, args: NativeArgs, obs: torch.Tensor, masks: torch.Tensor, actions: torch.Tensor,
             old_logprobs: torch.Tensor, adv: torch.Tensor, returns: torch.Tensor, logits: torch.Tensor,
             values: torch.Tensor, weight: torch.Tensor) -> tuple[torch.Tensor, dict[str, float]]:
    """The clipped PPO loss over the samples, each weighted by ``weight`` (1 for a valid
    step, 0 for an autoreset step); the advantages normalized over the weighted samples."""
    w = weight.float()
    n = w.sum().clamp(min=1.0)
    logp_all = torch.log_softmax(masked_logits(logits, masks), dim=-1)
    logp = logp_all.gather(-1, actions.unsqueeze(-1)).squeeze(-1)
    mean = (adv * w).sum() / n
    std = torch.sqrt((((adv - mean) ** 2) * w).sum() / n + 1e-8)
    a = torch.where(w > 0, (adv - mean) / std, torch.zeros_like(adv))
    ratio = torch.exp(torch.where(w > 0, logp - old_logprobs, torch.zeros_like(logp)))
    pg = torch.maximum(-a * ratio, -a * torch.clamp(ratio, 1 - args.clip_coef, 1 + args.clip_coef))
    pg_loss = (pg * w).sum() / n
    v_loss = 0.5 * (((values - returns) ** 2) * w).sum() / n
    entropy = -(logp_all.exp() * logp_all).sum(-1)
    ent = (entropy * w).sum() / n
    loss = pg_loss + args.vf_coef * v_loss - args.ent_coef * ent
    with torch.no_grad():
        kl = (((ratio - 1) - torch.log(ratio.clamp(min=1e-12))) * w).sum() / n
    return loss, {"policy_loss": float(pg_loss.detach()), "value_loss": float(v_loss.detach()), "entropy": float(ent.detach()),
                  "approx_kl": float(kl)}


def ppo_update(agent: Agent, optimizer: torch.optim.Optimizer, args: NativeArgs, r: Rollout,
               generator: torch.Generator | None = None) -> dict[str, float]:
    """``update_epochs`` passes of minibatch gradient steps over the rollout's valid steps
    (MLP: shuffled steps; GRU: shuffled envs, each replayed from the rollout's start)."""
    adv, returns = advantages(r, args.gamma, args.gae_lambda)
    T, N = r.rewards.shape
    info: dict[str, float] = {}
    for _ in range(args.update_epochs):
        if agent.kind == "mlp":
            flat = {k: v.reshape(T * N, *v.shape[2:]) for k, v in
                    (("obs", r.obs), ("masks", r.masks), ("actions", r.actions), ("logprobs", r.logprobs),
                     ("adv", adv), ("returns", returns))}
            for mb in minibatch_indices(r.valid, args.num_minibatches, generator):
                x = flat["obs"][mb]
                logits, values = agent.actor(x), agent.critic(x).squeeze(-1)
                loss, info = ppo_loss(agent, args, x, flat["masks"][mb], flat["actions"][mb], flat["logprobs"][mb],
                                      flat["adv"][mb], flat["returns"][mb], logits, values,
                                      torch.ones(mb.numel(), dtype=torch.bool, device=x.device))
                _step(agent, optimizer, loss, args.max_grad_norm)
        else:
            perm = torch.randperm(N, generator=generator).to(r.obs.device)
            for envs in torch.tensor_split(perm, args.num_minibatches):
                h = r.h0[envs]
                logit_list, value_list = [], []
                for t in range(T):
                    logits, values, h = agent.step(r.obs[t, envs], h, r.starts[t, envs])
                    logit_list.append(logits)
                    value_list.append(values)
                loss, info = ppo_loss(agent, args, r.obs[:, envs], r.masks[:, envs], r.actions[:, envs],
                                      r.logprobs[:, envs], adv[:, envs], returns[:, envs], torch.stack(logit_list),
                                      torch.stack(value_list), r.valid[:, envs])
                _step(agent, optimizer, loss, args.max_grad_norm)
    return info


def _step(agent: Agent, optimizer: torch.optim.Optimizer, loss: torch.Tensor, max_norm: float) -> None:
    optimizer.zero_grad(set_to_none=True)
    loss.backward()  # type: ignore[no-untyped-call]
    nn.utils.clip_grad_norm_(agent.parameters(), max_norm)
    optimizer.step()


# --------------------------------------------------------------------------- prioritized level replay


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

    def __init__(self, n_levels: int, score: str = "pvl", temperature: float = 0.1, staleness: float = 0.1,
                 seed: int = 0) -> None:
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
        return {"levels_seen": float(seen), "replay_share": self.replays / max(1, self.episodes),
                "mean_score": float(self.scores[self.seen].mean()) if seen else 0.0}


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


# --------------------------------------------------------------------------- greedy evaluation


BatchAct = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
"""A deterministic batched policy: ``(observations with memory, bool masks, episode
starts) -> actions``; it keeps its own recurrent state."""


def batch_verdicts(act: BatchAct, games: Sequence[Any], budgets: Sequence[int], where: slice | None,
                   obs_kind: str = "flat", seed: int = 0) -> dict[str, np.ndarray]:
    """Let a deterministic policy play every test of ``games`` once, all at once in one
    :class:`~flowtest_env.vector.PoolVectorEnv` (env ``i`` plays test ``i``), and return
    the verdict arrays: ``system_objective`` (``"met"``, ``"violated"``, ``"open"``),
    ``test_objective_realized``, ``restrictions``, ``steps``. Each test ends where the
    single env ends it: at its outcome or at its own step budget ``budgets[i]``.
    ``where``: the SUT's place in the observation, for the visited memory (``None``: none).
    """
    from flowtest_env.scoring import play_batch

    played = play_batch(WithVisited(act, where), games, runs=1, seed=seed, obs_kind=obs_kind, budgets=budgets)
    return {key: values[0] for key, values in played.items()}


class WithVisited:
    """A :data:`BatchAct` as a batched policy (``policy(obs, masks)`` with ``reset``) of
    :func:`flowtest_env.scoring.play_batch`: it feeds the policy the observation with the
    visited-places memory appended (the SUT's places seen so far, ``where`` in the
    observation; ``None``: no memory) and the episode-start flags of its first step."""

    def __init__(self, act: BatchAct, where: slice | None) -> None:
        self.act, self.where = act, where
        self.seen: np.ndarray | None = None
        self.starts = np.ones(0, dtype=bool)

    def reset(self, n: int, seed: int) -> None:
        self.seen, self.starts = None, np.ones(n, dtype=bool)

    def __call__(self, obs: np.ndarray, masks: np.ndarray) -> np.ndarray:
        x = obs
        if self.where is not None:
            now = obs[:, self.where].astype(np.float32)
            self.seen = now if self.seen is None else np.maximum(self.seen, now)
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
            logits, _, self.h = self.agent.step(xt, self.h, st)
            logits = masked_logits(logits, torch.as_tensor(np.asarray(masks, dtype=bool), device=self.device))
            out: np.ndarray = torch.argmax(logits, dim=-1).cpu().numpy()
            return out


class BatchActor:
    """A native agent as a batched policy of :mod:`flowtest_env.scoring`:
    ``actor(observations, masks) -> actions`` on the env's own observations (the actor adds
    the visited-places memory itself when the agent was trained with it, and carries the
    GRU state). ``deterministic``: the most likely legal action (greedy); otherwise one
    sampled from the masked policy with a torch generator that ``reset(n, seed)`` seeds,
    so the same seed gives the same runs.

    Example::

        from flowtest_env.scoring import score_policy
        model = load_native("policy.zip")
        greedy = score_policy(model.batch_policy(), pool="reachability1/5x5", split="test", count=1000)
        sampled = score_policy(model.batch_policy(deterministic=False), pool="reachability1/5x5", split="test",
                               count=1000, runs=8)
    """

    def __init__(self, agent: Agent, where: slice | None, deterministic: bool = True, device: str | torch.device = "cpu") -> None:
        self.agent, self.where, self.deterministic = agent, where, deterministic
        self.device = torch.device(device)
        self.memory = VisitedBits(where)
        self.h: torch.Tensor | None = None
        self.start = True
        self.generator = torch.Generator(device=self.device).manual_seed(0)

    def reset(self, num_runs: int, seed: int) -> None:
        """Before a batch of runs: forget the memory and the GRU state; seed the sampling."""
        self.memory = VisitedBits(self.where)
        self.h = None
        self.start = True
        self.generator = torch.Generator(device=self.device).manual_seed(int(seed))

    def __call__(self, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            obs = torch.as_tensor(np.asarray(observations, dtype=np.float32), device=self.device)
            n = obs.shape[0]
            start = torch.full((n,), self.start, dtype=torch.bool, device=self.device)
            self.start = False
            x = self.memory(obs, start)
            if self.h is None or self.h.shape[0] != n:
                self.h = self.agent.initial_state(n, self.device)
            if self.agent.kind == "mlp":  # acting needs no value
                logits = self.agent.actor(x)
            else:
                logits, _, self.h = self.agent.step(x, self.h, start)
            logits = masked_logits(logits, torch.as_tensor(np.asarray(masks, dtype=bool), device=self.device))
            if self.deterministic:
                a = torch.argmax(logits, dim=-1)
            else:
                u = torch.rand(logits.shape, generator=self.generator, device=self.device).clamp_(1e-12, 1.0)
                a = torch.argmax(logits - torch.log(-torch.log(u)), dim=-1)
            out: np.ndarray = a.cpu().numpy()
            return out


def met_rate(agent: Agent, games: Sequence[Any], budgets: Sequence[int], where: slice | None, obs_kind: str,
             device: torch.device) -> dict[str, float]:
    """Greedy play of every test once: the share met and realized (of all tests), mean restrictions."""
    was = agent.training
    agent.eval()
    v = batch_verdicts(GreedyActor(agent, device), games, budgets, where, obs_kind)
    agent.train(was)
    met = v["system_objective"] == "met"
    return {"met": float(met.mean()), "realized": float((met & v["test_objective_realized"]).mean()),
            "restrictions": float(v["restrictions"].mean())}


# --------------------------------------------------------------------------- logging


class Logs:
    """CSV always (``progress.csv``, rewritten atomically at every row), TensorBoard when
    the ``tensorboard`` package is there (a one-line note on stderr when not)."""

    def __init__(self, log_dir: str | Path | None, quiet: bool = False) -> None:
        self.dir = Path(log_dir) if log_dir is not None else None
        self.rows: list[dict[str, Any]] = []
        self.writer: Any = None
        if self.dir is None:
            return
        self.dir.mkdir(parents=True, exist_ok=True)
        try:
            from torch.utils.tensorboard import SummaryWriter
        except ImportError:
            if not quiet:
                sys.stderr.write("flowtest: TensorBoard logs need the tensorboard package (pip install 'flowtest[rl]'); "
                                 "writing progress.csv only\n")
            return
        self.writer = SummaryWriter(str(self.dir))

    def add(self, step: int, values: dict[str, float]) -> None:
        """One row: scalars at ``step``."""
        row = {"step": step, **{k: round(v, 6) if isinstance(v, float) else v for k, v in values.items()}}
        self.rows.append(row)
        if self.writer is not None:
            for k, v in values.items():
                self.writer.add_scalar(k, v, step)
        if self.dir is not None:
            self._write_csv()

    def _write_csv(self) -> None:
        assert self.dir is not None
        keys = list(dict.fromkeys(k for row in self.rows for k in row))
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=keys)
        w.writeheader()
        w.writerows(self.rows)
        path = self.dir / "progress.csv"
        tmp = path.with_name(f".progress.{os.getpid()}.tmp")
        try:
            tmp.write_text(buf.getvalue())
            os.replace(tmp, path)
        finally:
            tmp.unlink(missing_ok=True)

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()


# --------------------------------------------------------------------------- the loop


@dataclass
class TrainResult:
    """What a run did: its settings, the steps taken, training seconds (evaluations
    excluded), steps per second, the greedy evaluations (``[(step, {split: rates})]``)
    and the final ones, and the checkpoint's path (``None`` if not saved)."""

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

    @property
    def steps_per_second(self) -> float:
        return self.steps / self.seconds if self.seconds > 0 else 0.0


def _budgets(games: Sequence[Any]) -> list[int]:
    from flowtest_env.envs import default_max_steps

    return [default_max_steps(g) for g in games]


def train(args: NativeArgs, out: str | Path | None = None, heldout: Sequence[Any] = (), log_dir: str | Path | None = None,
          progress_bar: bool = True, evaluate_train: bool | int = True, env: Any = None) -> TrainResult:
    """Train a masked PPO agent (see the module docstring), evaluating it greedily on the
    env's own tests (the train tests; with ``evaluate_train=N`` the first ``N`` of them) and
    on ``heldout`` games every ``args.eval_every`` steps and at the end; save the checkpoint
    to ``out`` (atomically) when given.

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
    where = shared_position_slice(games, args.obs_kind) if args.memory == "visited" else None
    mem_size = where.stop - where.start if where is not None else 0
    obs_size = int(np.prod(env.single_observation_space.shape)) - (mem_size if env_memory else 0)  # without memory
    net = network_settings(args)
    agent = Agent(obs_size + mem_size, n_actions, net["hidden"], net["kind"], net["gru_hidden"]).to(device)
    optimizer = torch.optim.Adam(agent.parameters(), lr=args.learning_rate, eps=1e-5)
    generator = torch.Generator().manual_seed(args.seed)
    sampler = level_sampler(args, inner, len(games))
    runner = Runner(env, agent, None if env_memory else where, device, args.seed,
                    levels=(lambda: np.asarray(inner.test_index)) if sampler is not None else None)
    shown = games if evaluate_train is True else games[:int(evaluate_train)]
    splits = {"train": (shown, _budgets(shown))} if evaluate_train and games else {}
    if heldout:
        splits["heldout"] = (list(heldout), _budgets(heldout))
    logs = Logs(log_dir, quiet=not progress_bar)
    total = math.ceil(args.total_steps / args.num_envs) * args.num_envs  # whole steps of every env
    evaluations: list[tuple[int, dict[str, dict[str, float]]]] = []
    eval_seconds = 0.0
    next_eval = 0

    def evaluate(step: int) -> dict[str, dict[str, float]]:
        nonlocal eval_seconds
        t = time.perf_counter()
        rates = {name: met_rate(agent, g, b, where, args.obs_kind, device) for name, (g, b) in splits.items()}
        eval_seconds += time.perf_counter() - t
        evaluations.append((step, rates))
        logs.add(step, {f"eval/{name}_{k}": v for name, r in rates.items() for k, v in r.items()})
        return rates

    bar = None
    if progress_bar:
        from tqdm import tqdm

        bar = tqdm(total=total, unit="step", desc="training", file=sys.stderr, mininterval=1.0, unit_scale=True)
    t0 = time.perf_counter()
    step = 0
    try:
        while step < total:
            if splits and args.eval_every and step >= next_eval:
                evaluate(step)
                while next_eval <= step:
                    next_eval += args.eval_every
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
            logs.add(step, {"train/steps_per_second": step / max(elapsed, 1e-9), "train/lr": optimizer.param_groups[0]["lr"],
                            **{f"episode/{k}": v for k, v in episode.items()}, **{f"loss/{k}": v for k, v in info.items()},
                            **info_plr})
            if bar is not None:
                bar.update(num_steps * args.num_envs)
                if "met" in episode:
                    bar.set_postfix(met=f"{100 * episode['met']:.0f}%", refresh=False)
        seconds = time.perf_counter() - t0 - eval_seconds
        final = evaluate(step) if splits else {}
    finally:
        if bar is not None:
            bar.close()
        logs.close()
    settings = checkpoint_settings(args, inner, obs_size, n_actions, where, step)
    settings["trained_on"] = str(device)
    path = None
    if out is not None:
        path = Path(out)
        save_policy(path, agent, settings)
    return TrainResult(args, step, seconds, eval_seconds, evaluations, final, path, agent, settings, logs.rows)


# --------------------------------------------------------------------------- the checkpoint


def checkpoint_settings(args: NativeArgs, env: Any, obs_size: int, n_actions: int, where: slice | None,
                        steps: int) -> dict[str, Any]:
    """The plain settings saved next to the tensors (:mod:`agents.checkpoint`)."""
    import flowtest_env

    training = asdict(args)
    training["hidden"] = list(args.hidden)
    return {
        "algo": args.algo, "network": network_settings(args),
        "obs": {"obs_kind": args.obs_kind, "pad_to": 8, "size": obs_size},
        "memory": args.memory, "position": [where.start, where.stop] if where else None,
        "obs_size": obs_size + (where.stop - where.start if where else 0), "n_actions": n_actions,
        "env": {"id": args.env_id, "options": dict(args.env_kwargs), "problem": str(getattr(env, "problem", ""))},
        "training": training, "steps": steps,
        "versions": {"flowtest": getattr(flowtest_env, "__version__", _flowtest_version()), "torch": torch.__version__,
                     "numpy": np.__version__},
    }


def _flowtest_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("flowtest")
    except PackageNotFoundError:  # pragma: no cover - run from a source tree without install
        return "unknown"


def save_policy(path: str | Path, agent: Agent, settings: dict[str, Any]) -> None:
    """Write ``agent`` as a native checkpoint (atomic)."""
    tensors = {k: v.detach().cpu().numpy() for k, v in agent.state_dict().items()}
    save_checkpoint(path, settings, tensors)


def agent_from_checkpoint(ck: Checkpoint) -> Agent:
    """Rebuild the network of a checkpoint and load its tensors.

    Raises
    ------
    CheckpointError
        If the settings do not describe a network these tensors fit.
    """
    s = ck.settings
    try:
        net = s["network"]
        agent = Agent(int(s["obs_size"]), int(s["n_actions"]), [int(w) for w in net["hidden"]], str(net["kind"]),
                      int(net["gru_hidden"]))
        want = agent.state_dict()
        if set(want) != set(ck.tensors):
            raise CheckpointError(f"tensors {sorted(ck.tensors)} do not match the network's {sorted(want)}")
        agent.load_state_dict({k: torch.from_numpy(np.array(v)) for k, v in ck.tensors.items()})
    except (KeyError, TypeError, ValueError, RuntimeError) as exc:
        if isinstance(exc, CheckpointError):
            raise
        raise CheckpointError(f"the settings do not describe this network ({type(exc).__name__}: {exc})") from None
    agent.eval()
    return agent


class NativeModel:
    """A loaded native checkpoint with the small part of stable-baselines3's model
    interface FlowTest's players use (``predict``, ``observation_space``), so
    :class:`agents.ppo.PPOPolicy` plays it like any saved model. Always masked; recurrent
    for a GRU network. Runs on the CPU."""

    maskable = True

    def __init__(self, ck: Checkpoint) -> None:
        from gymnasium import spaces

        self.checkpoint = ck
        self.settings = ck.settings
        self.agent = agent_from_checkpoint(ck)
        self.recurrent = self.agent.kind == "gru"
        self.flowtest_memory = str(ck.settings.get("memory", "none"))
        obs = ck.settings.get("obs", {})
        self.flowtest_obs = {"obs_kind": str(obs.get("obs_kind", "flat")), "pad_to": int(obs.get("pad_to", 8))}
        self.observation_space = spaces.Box(0.0, 1.0, shape=(self.agent.obs_size,), dtype=np.float32)
        self._actor = GreedyActor(self.agent, torch.device("cpu"))
        pos = ck.settings.get("position")
        self.position = slice(int(pos[0]), int(pos[1])) if self.flowtest_memory == "visited" and pos else None

    def batch_policy(self, deterministic: bool = True) -> BatchActor:
        """This model as a batched policy of :mod:`flowtest_env.scoring` (greedy, or
        sampled from its masked policy): :class:`BatchActor`."""
        return BatchActor(self.agent, self.position, deterministic)

    def predict(self, obs: Any, state: Any = None, episode_start: Any = None, deterministic: bool = True,
                action_masks: Any = None) -> tuple[np.ndarray, Any]:
        """The most likely legal action for one observation or a batch (``state``: the
        GRU state returned by the previous call; ``episode_start``: which rows begin an
        episode). Sampling is not offered: FlowTest plays its policies greedily."""
        x = np.asarray(obs, dtype=np.float32)
        single = x.ndim == 1
        x2 = x[None] if single else x
        n = x2.shape[0]
        masks = np.ones((n, self.agent.n_actions), dtype=bool) if action_masks is None else np.asarray(action_masks, dtype=bool)
        masks = masks.reshape(n, -1)
        starts = np.ones(n, dtype=bool) if episode_start is None else np.asarray(episode_start, dtype=bool).reshape(n)
        self._actor.h = state if isinstance(state, torch.Tensor) and state.shape[0] == n else None
        actions = self._actor(x2, masks, starts)
        return (actions[0] if single else actions), self._actor.h


def load_native(path: str | Path) -> NativeModel:
    """A native checkpoint as a :class:`NativeModel` (never unpickled).

    Raises
    ------
    CheckpointError
        If the file is not a valid native checkpoint.
    """
    return NativeModel(load_checkpoint(path))


__all__ = ["ALGOS", "NativeArgs", "Agent", "BatchActor", "LevelSampler", "Rollout", "Runner", "TrainResult", "NativeModel", "advantages",
           "batch_verdicts", "check_args", "collect_rollout", "load_native", "masked_logits", "minibatch_indices",
           "ppo_update", "resolve_device", "save_policy", "train"]
