"""Training and env throughput side by side, in one run: the native trainer against
stable-baselines3's MaskablePPO on the same pool and network, and the NumPy vector env
against its torch twin.

    python -m experiments.lab.bench_training --out bench-training.json

Rows (each timed after its setup: the pool loaded, the model built):

* **training, end to end** (env steps per second of training, rollouts and updates):
  - ``native (torch env)`` and ``native (numpy env)``: :mod:`agents.native_ppo` with
    ``flowtest train``'s defaults (:data:`~experiments.training.settings.NATIVE_DEFAULTS`:
    128 envs x 32 steps, minibatches of 1,024, 4 epochs; the NumPy env is the default on the CPU);
  - ``sb3 MaskablePPO (flowtest defaults)``: ``flowtest train --trainer sb3``'s settings
    (8 single envs x 128 steps, minibatches of 256, 10 epochs);
  - ``sb3 MaskablePPO (native's PPO settings)``: the native defaults' envs, steps,
    minibatch and epochs (128 single envs x 32 steps, minibatches of 1,024, 4 epochs): the
    same updates as the native run, so the difference is the implementation only;
  all with the same network (``--net-arch``, actor and critic each, tanh), the visited-places
  memory, no shaping, one torch thread, on ``--pool``'s first ``--count`` train tests;
* **env alone** (steps per second, random legal actions chosen in the same library,
  ``memory="visited"``, ``--env-envs`` envs): the NumPy vector env and the torch env on
  the CPU (and on CUDA when torch sees a GPU).

Prints a table and writes the figures, the command, the machine and its load as JSON.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from experiments.training.settings import NATIVE_DEFAULTS

POOL_ENV_ID = "FlowTest-RandomGrid-v0"


def _load() -> list[float]:
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:  # pragma: no cover
        return []


def native_row(name: str, pool: dict[str, Any], steps: int, net: list[int], backend: str) -> dict[str, Any]:
    """The native trainer's steps per second (training loop; no evaluation)."""
    from agents.native_ppo import NativeArgs, train

    args = NativeArgs(env_id=POOL_ENV_ID, env_kwargs=pool, total_steps=steps, hidden=tuple(net), device="cpu", eval_every=0, env_backend=backend)
    r = train(args, progress_bar=False, evaluate_train=False)
    return {
        "row": name,
        "kind": "training",
        "steps": r.steps,
        "seconds": round(r.seconds, 2),
        "steps_per_second": round(r.steps_per_second, 1),
        "settings": {
            "n_envs": args.num_envs,
            "n_steps": args.num_steps,
            "minibatch": args.batch_size() // args.num_minibatches,
            "epochs": args.update_epochs,
            "net_arch": net,
            "env": backend,
        },
    }


def sb3_row(name: str, pool: dict[str, Any], steps: int, net: list[int], settings: dict[str, Any]) -> dict[str, Any]:
    """MaskablePPO's steps per second (``model.learn`` only)."""
    from experiments.training.settings import DEFAULTS
    from experiments.training.system import make_model, make_training_vec_env

    s = {**DEFAULTS, "net_arch": list(net), "shaping": 0.0, "memory": "visited", **settings}
    env = make_training_vec_env(POOL_ENV_ID, 0, s, pool)
    model = make_model(env, s, 0)
    t0 = time.perf_counter()
    model.learn(total_timesteps=steps)
    seconds = time.perf_counter() - t0
    env.close()
    return {
        "row": name,
        "kind": "training",
        "steps": int(model.num_timesteps),
        "seconds": round(seconds, 2),
        "steps_per_second": round(model.num_timesteps / seconds, 1),
        "settings": {
            "n_envs": s["n_envs"],
            "n_steps": s["n_steps"],
            "minibatch": s["batch_size"],
            "epochs": s["n_epochs"],
            "net_arch": net,
            "env": "single envs (DummyVecEnv)",
        },
    }


def numpy_env_row(pool: dict[str, Any], n: int, steps: int) -> dict[str, Any]:
    """The NumPy vector env alone, random legal actions (NumPy)."""
    import gymnasium as gym

    import flowtest_env  # noqa: F401

    env: Any = gym.make_vec(POOL_ENV_ID, num_envs=n, vectorization_mode="vector_entry_point", memory="visited", **pool)
    _, infos = env.reset(seed=0)
    rng = np.random.default_rng(0)
    t0 = time.perf_counter()
    for _ in range(steps):
        a = np.argmax(infos["action_mask"] * rng.random(infos["action_mask"].shape), axis=1)
        _, _, _, _, infos = env.step(a)
    seconds = time.perf_counter() - t0
    return {
        "row": "env: numpy vector env (CPU)",
        "kind": "env",
        "steps": n * steps,
        "seconds": round(seconds, 2),
        "steps_per_second": round(n * steps / seconds, 1),
        "settings": {"num_envs": n, "memory": "visited"},
    }


def torch_env_row(pool: dict[str, Any], n: int, steps: int, device: str) -> dict[str, Any]:
    """The torch env alone on ``device``, random legal actions (torch)."""
    import torch

    from flowtest_env.torch_vector import make_vec

    env = make_vec(POOL_ENV_ID, n, device=device, memory="visited", **pool)
    _, infos = env.reset(seed=0)
    gen = torch.Generator(device=device).manual_seed(0)
    mask = infos["action_mask"]
    for _ in range(3):  # warm-up (CUDA kernels)
        a = torch.argmax(mask * torch.rand(mask.shape, generator=gen, device=device), dim=1)
        _, _, _, _, infos = env.step(a)
        mask = infos["action_mask"]
    if device.startswith("cuda"):
        torch.cuda.synchronize()
    t0 = time.perf_counter()
    for _ in range(steps):
        a = torch.argmax(mask * torch.rand(mask.shape, generator=gen, device=device), dim=1)
        _, _, _, _, infos = env.step(a)
        mask = infos["action_mask"]
    if device.startswith("cuda"):
        torch.cuda.synchronize()
    seconds = time.perf_counter() - t0
    return {
        "row": f"env: torch env ({device})",
        "kind": "env",
        "steps": n * steps,
        "seconds": round(seconds, 2),
        "steps_per_second": round(n * steps / seconds, 1),
        "settings": {"num_envs": n, "memory": "visited"},
    }


def table(rows: list[dict[str, Any]], base: float | None) -> str:
    """The Markdown table (training rows with their speed-up over the first SB3 row)."""
    lines = ["| row | steps | seconds | steps/s | x sb3 (flowtest defaults) | settings |", "|---|---|---|---|---|---|"]
    for r in rows:
        ratio = f"{r['steps_per_second'] / base:.1f}x" if base and r["kind"] == "training" else ""
        settings = ", ".join(f"{k} {v}" for k, v in r["settings"].items())
        lines.append(f"| {r['row']} | {r['steps']:,} | {r['seconds']} | {r['steps_per_second']:,.0f} | {ratio} | {settings} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--pool", default="reachability1/5x5")
    p.add_argument("--count", type=int, default=128, help="train tests (default 128)")
    p.add_argument(
        "--net-arch",
        default=",".join(map(str, NATIVE_DEFAULTS["net_arch"])),
        help="hidden widths of actor and critic (default: the native trainer's, 64,64)",
    )
    p.add_argument("--native-steps", type=int, default=131_072)
    p.add_argument("--sb3-steps", type=int, default=8_192)
    p.add_argument("--env-envs", type=int, default=1024)
    p.add_argument("--env-steps", type=int, default=200)
    p.add_argument("--skip-sb3", action="store_true")
    p.add_argument("--out", type=Path, default=None, help="write the figures as JSON here")
    args = p.parse_args(argv)
    import torch

    torch.set_num_threads(1)
    net = [int(w) for w in args.net_arch.split(",")]
    pool = {"pool": args.pool, "split": "train", "count": args.count}
    load_before = _load()
    rows: list[dict[str, Any]] = []

    def add(row: dict[str, Any]) -> None:
        rows.append(row)
        print(f"{row['row']}: {row['steps_per_second']:,.0f} steps/s ({row['steps']:,} steps in {row['seconds']} s)", file=sys.stderr, flush=True)

    if not args.skip_sb3:
        add(sb3_row("sb3 MaskablePPO (flowtest defaults)", pool, args.sb3_steps, net, {}))
        same = {k: NATIVE_DEFAULTS[k] for k in ("n_envs", "n_steps", "batch_size", "n_epochs")}
        add(sb3_row("sb3 MaskablePPO (native's PPO settings)", pool, args.sb3_steps, net, same))
    add(native_row("native (torch env on the CPU)", pool, args.native_steps, net, "torch"))
    add(native_row("native (numpy env, the default on the CPU)", pool, args.native_steps, net, "numpy"))
    add(numpy_env_row(pool, args.env_envs, args.env_steps))
    add(torch_env_row(pool, args.env_envs, args.env_steps, "cpu"))
    if torch.cuda.is_available():
        add(torch_env_row(pool, args.env_envs, args.env_steps, "cuda"))
    base = rows[0]["steps_per_second"] if not args.skip_sb3 else None
    md = table(rows, base)
    print(md)
    doc = {
        "command": "python -m experiments.lab.bench_training " + " ".join(argv if argv is not None else sys.argv[1:]),
        "machine": {
            "cpus": os.cpu_count(),
            "processor": platform.processor() or platform.machine(),
            "torch": torch.__version__,
            "torch_threads": torch.get_num_threads(),
            "cuda": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None,
        },
        "load_before": load_before,
        "load_after": _load(),
        "rows": rows,
        "table": md,
    }
    if args.out is not None:
        args.out.write_text(json.dumps(doc, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
