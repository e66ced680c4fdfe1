"""The env a native run steps (CleanRL's ``make_env``) and the memory the trainer keeps
beside it: :func:`make_vec_env` (the NumPy vector env, or its torch twin on the training
device); the place memory of a batch is :class:`flowtest_env.torch_memory.BatchPlaceMemory`.

Example::

    from agents.native.args import NativeArgs
    from agents.native.envs import make_vec_env
    np_env, env, env_memory = make_vec_env(NativeArgs(env_id="FlowTest-Maze2-v0", num_envs=16, device="cpu"))
"""

from __future__ import annotations

from typing import Any

from flowtest_env.memory import PLACE_MEMORIES

from .args import NativeArgs, resolve_device


def make_vec_env(args: NativeArgs) -> tuple[Any, Any, bool]:
    """``args.num_envs`` runs of ``args.env_id`` with the env options of ``args``: the
    NumPy vector env (``vectorization_mode="vector_entry_point"``), and the env to step
    (that one, or with ``env_backend="torch"`` its torch twin on the training device);
    and whether the env itself appends the place memory (``memory="visited"`` or ``"counts"``).

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
    env_memory = args.memory in PLACE_MEMORIES
    with_memory: dict[str, Any] = {**kwargs, "memory": args.memory} if env_memory else kwargs
    try:
        try:
            np_env = gym.make_vec(args.env_id, num_envs=args.num_envs, vectorization_mode="vector_entry_point", **with_memory)
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


__all__ = ["make_vec_env"]
