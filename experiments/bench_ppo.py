"""PPO benchmark: train MaskablePPO on ``FlowTest-Maze2-v0`` until the system objective is
met in at least 95 % of 100 evaluation runs; print the steps and wall time it took.

Trains in rounds of ``--chunk`` time steps (one model, training continued), evaluating
after each round, up to ``--max-steps``. Run: ``python -m experiments.bench_ppo``.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    """Train until the target success rate (exit 0) or the step budget runs out (exit 1)."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--env", default="FlowTest-Maze2-v0")
    p.add_argument("--target", type=float, default=0.95)
    p.add_argument("--chunk", type=int, default=10_000)
    p.add_argument("--max-steps", type=int, default=200_000)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    from sb3_contrib import MaskablePPO
    import torch

    from experiments.train import DEFAULTS, make_training_env, success_rate

    torch.manual_seed(args.seed)
    torch.set_num_threads(1)
    env = make_training_env(args.env, args.seed, DEFAULTS["gamma"], DEFAULTS["shaping"])
    model = MaskablePPO(
        "MlpPolicy", env, seed=args.seed, device="cpu", n_steps=DEFAULTS["n_steps"],
        batch_size=DEFAULTS["batch_size"], learning_rate=DEFAULTS["learning_rate"], gamma=DEFAULTS["gamma"],
        ent_coef=DEFAULTS["ent_coef"], n_epochs=DEFAULTS["n_epochs"], policy_kwargs={"net_arch": DEFAULTS["net_arch"]},
    )
    t0, steps, rate = time.perf_counter(), 0, 0.0
    while steps < args.max_steps:
        model.learn(total_timesteps=args.chunk, reset_num_timesteps=False)
        steps += args.chunk
        train_s = time.perf_counter() - t0
        rate = success_rate(model, args.env, 100)
        print(f"{steps:7d} steps  {train_s:7.1f} s  success {100 * rate:5.1f} %", flush=True)
        if rate >= args.target:
            out = Path(tempfile.gettempdir()) / "flowtest-bench-ppo.zip"
            model.save(str(out))
            print(f"reached {100 * rate:.0f} % after {steps} steps, {train_s:.1f} s wall time; model {out}")
            return 0
    print(f"not reached: {100 * rate:.0f} % after {steps} steps", file=sys.stderr)
    return 1


if __name__ == "__main__":
    raise SystemExit(main())
