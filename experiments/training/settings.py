"""The settings of FlowTest's two trainers of a system under test, checked before any work.

``flowtest train`` and ``flowtest benchmark`` (its baselines) train with these. The native
trainer (:mod:`agents.native_ppo`; :data:`NATIVE_DEFAULTS`, :func:`native_settings`,
:func:`native_args`) and stable-baselines3 (:data:`DEFAULTS`, :func:`check_settings`) each
have their own table; the settings that are env options (:data:`ENV_OPTION_KEYS`,
:func:`env_options`) are printed at the start and saved with the model. A setting is named on
the command line by :func:`flag_of` (``n_envs`` is ``--n-envs``).
"""

from __future__ import annotations

from typing import Any

from synthesis.model.errors import ProblemError

ALGOS = ("maskable-ppo", "recurrent-ppo")
"""``--algo`` choices: sb3-contrib's MaskablePPO (MLP policy, action masks) and
RecurrentPPO (LSTM policy, no masks)."""

DEFAULTS: dict[str, Any] = {
    "algo": "maskable-ppo",
    "n_envs": 8,
    "n_steps": 128,
    "batch_size": 256,
    "learning_rate": 1e-3,
    "gamma": 0.99,
    "ent_coef": 0.01,
    "n_epochs": 10,
    "net_arch": [64, 64],
    "lstm_hidden_size": 256,
    "shaping": 10.0,
    "memory": "visited",
    "obs_kind": "flat",
    "pad_to": 8,
}
"""Training settings: the algorithm; 8 envs stepped in one process (one batched policy
call per step of all eight), rollouts of 8 x 128 steps, a small network, a high learning
rate; the LSTM's width (RecurrentPPO only; sb3-contrib's default); the env options: the
shaping scale (0 = off), the SUT's memory, the observation (``pad_to`` is used by
``obs_kind="padded"`` only)."""

ENV_OPTION_KEYS = ("memory", "shaping", "obs_kind", "pad_to")
"""The settings that are env options (the rest configure the algorithm)."""


def env_options(settings: dict[str, Any]) -> dict[str, Any]:
    """The env options of ``settings`` (keyword arguments of :class:`flowtest_env.FlowTestEnv`)."""
    opts: dict[str, Any] = {
        "memory": settings["memory"],
        "shaping": float(settings["shaping"]),
        "shaping_gamma": float(settings["gamma"]),
        "obs_kind": settings["obs_kind"],
    }
    if settings["obs_kind"] == "padded":
        opts["pad_to"] = int(settings["pad_to"])
    return opts


def check_settings(settings: dict[str, Any]) -> None:
    """Reject settings no algorithm can use, as invalid input.

    Raises
    ------
    ProblemError
        On an unknown key or algorithm, or a value out of range.
    """
    unknown = set(settings) - set(DEFAULTS)
    if unknown:
        raise ProblemError(f"unknown training settings {sorted(unknown)}; known: {', '.join(DEFAULTS)}")
    if settings["algo"] not in ALGOS:
        raise ProblemError(f"unknown --algo {settings['algo']!r}; expected one of {', '.join(ALGOS)}")
    for key in ("n_envs", "n_steps", "batch_size", "n_epochs", "lstm_hidden_size"):
        if int(settings[key]) < 1:
            raise ProblemError(f"--{key.replace('_', '-')} must be at least 1")
    if not 0 < float(settings["gamma"]) <= 1:
        raise ProblemError("--gamma must be in (0, 1]")
    if float(settings["learning_rate"]) <= 0:
        raise ProblemError("--learning-rate must be positive")
    if float(settings["shaping"]) < 0:
        raise ProblemError("--shaping must be 0 (off) or a positive scale")
    if not settings["net_arch"] or any(int(w) < 1 for w in settings["net_arch"]):
        raise ProblemError("--net-arch must be positive layer widths, e.g. 64,64")


TRAINERS = ("native", "sb3")
"""``--trainer`` choices: FlowTest's own batched PPO (default) and stable-baselines3."""

NATIVE_ALGOS = ("ppo", "recurrent-ppo")
"""The native trainer's ``--algo`` (``maskable-ppo`` is taken as ``ppo``: both mask)."""

NATIVE_DEFAULTS: dict[str, Any] = {
    "algo": "ppo",
    "n_envs": 128,
    "n_steps": 32,
    "batch_size": 1024,
    "n_epochs": 4,
    "learning_rate": 3e-3,
    "gamma": 0.99,
    "gae_lambda": 0.95,
    "clip_range": 0.2,
    "ent_coef": 0.01,
    "vf_coef": 0.5,
    "max_grad_norm": 0.5,
    "net_arch": [64, 64],
    "gru_hidden_size": 128,
    "shaping": 0.0,
    "memory": "visited",
    "obs_kind": "flat",
    "pad_to": 8,
    "device": "auto",
    "env_backend": "auto",
    "threads": 1,
}
"""The native trainer's settings: 128 envs x 32 steps per rollout (4,096 steps), minibatches
of 1,024 steps, 4 epochs, Adam at 3e-3 annealed to 0, an MLP of 64 x 64 (actor and critic
each, tanh), the visited-places memory, no shaping, one CPU thread (a seed gives the same
run). Chosen by time to a score (docs/training.md, *The defaults*): against the earlier 256 x
256, 2 epochs, 1e-3 they fit ``reachability1/5x5-v2``'s 128 train tests 5x sooner and reach a
higher held-out met. ``--algo recurrent-ppo`` changes :data:`NATIVE_RECURRENT` unless given."""

NATIVE_RECURRENT: dict[str, Any] = {"memory": "none", "net_arch": [128], "n_epochs": 2, "learning_rate": 1e-3}
"""The recurrent variant's own defaults: its GRU is its memory, one input layer, and the
update it was measured with (2 epochs at 1e-3)."""


def native_settings(overrides: dict[str, Any]) -> dict[str, Any]:
    """The native trainer's full settings: :data:`NATIVE_DEFAULTS`, the recurrent
    defaults for ``recurrent-ppo``, then ``overrides``.

    Raises
    ------
    ProblemError
        On a setting of the sb3 trainer only, an unknown algorithm or a value out of range.
    """
    unknown = set(overrides) - set(NATIVE_DEFAULTS)
    if unknown:
        flags = ", ".join(flag_of(k) for k in sorted(unknown))
        raise ProblemError(f"{flags}: a setting of --trainer sb3, not of the native trainer")
    algo = "ppo" if overrides.get("algo", "ppo") == "maskable-ppo" else overrides.get("algo", "ppo")
    if algo not in NATIVE_ALGOS:
        raise ProblemError(f"--algo {algo}: the native trainer has {', '.join(NATIVE_ALGOS)}")
    settings = {**NATIVE_DEFAULTS, **(NATIVE_RECURRENT if algo == "recurrent-ppo" else {}), **overrides, "algo": algo}
    if settings["obs_kind"] == "grid":
        raise ProblemError("--obs-kind grid: the native trainer reads flat or padded observations")
    if settings["obs_kind"] == "padded" and int(settings["pad_to"]) != 8:
        raise ProblemError("--pad-to: the vector env pads to 8 x 8 only")
    from agents.native.args import check_args

    try:
        check_args(native_args(settings, "FlowTest-v0", {}, 1, 0))
    except ValueError as exc:
        raise ProblemError(f"training settings: {exc}") from None
    return settings


def native_args(settings: dict[str, Any], env_id: str, env_kwargs: dict[str, Any], steps: int, seed: int, eval_every: int = 0) -> Any:
    """The :class:`agents.native_ppo.NativeArgs` of ``settings`` (flag names as the sb3
    trainer's: ``n_envs``, ``n_steps``, ``batch_size`` (a minibatch), ``n_epochs``, ``net_arch``)."""
    from agents.native.args import NativeArgs

    n_envs, n_steps = int(settings["n_envs"]), int(settings["n_steps"])
    minibatches = max(1, (n_envs * n_steps) // max(1, int(settings["batch_size"])))
    if settings["algo"] == "recurrent-ppo":  # whole env sequences per minibatch
        minibatches = min(minibatches, n_envs)
        while n_envs % minibatches:
            minibatches -= 1
    return NativeArgs(
        env_id=env_id,
        env_kwargs=dict(env_kwargs),
        algo=settings["algo"],
        total_steps=int(steps),
        num_envs=n_envs,
        num_steps=n_steps,
        num_minibatches=minibatches,
        update_epochs=int(settings["n_epochs"]),
        learning_rate=float(settings["learning_rate"]),
        gamma=float(settings["gamma"]),
        gae_lambda=float(settings["gae_lambda"]),
        clip_coef=float(settings["clip_range"]),
        ent_coef=float(settings["ent_coef"]),
        vf_coef=float(settings["vf_coef"]),
        max_grad_norm=float(settings["max_grad_norm"]),
        hidden=tuple(int(w) for w in settings["net_arch"]),
        gru_hidden=int(settings["gru_hidden_size"]),
        memory=settings["memory"],
        obs_kind=settings["obs_kind"],
        shaping=float(settings["shaping"]),
        seed=int(seed),
        device=str(settings["device"]),
        threads=int(settings["threads"]),
        eval_every=int(eval_every),
        env_backend=str(settings["env_backend"]),
    )


def flag_of(key: str) -> str:
    """The command-line flag of a setting: ``n_envs`` is ``--n-envs``."""
    return "--" + key.replace("_", "-")
