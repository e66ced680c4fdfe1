"""PPO benchmark: train MaskablePPO on ``FlowTest-Maze2-v0`` until the system objective is
met in at least 95 % of 100 evaluation runs; print the steps and wall time it took.

Trains in rounds of ``--chunk`` time steps (one model, training continued), evaluating
after each round, up to ``--max-steps``. The settings are :data:`experiments.training.settings.DEFAULTS`
(the ones ``flowtest train`` uses); ``--set KEY=VALUE`` changes one (a JSON value), e.g.
``--set memory='"none"'`` or ``--set shaping=0`` for the ablations in docs/benchmarks.md.
The wall time counts training only; evaluation runs are timed apart.
Run: ``python -m experiments.lab.bench_ppo``.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    """Train until the target success rate (exit 0) or the step budget runs out (exit 1)."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--env", default="FlowTest-Maze2-v0")
    p.add_argument("--target", type=float, default=0.95)
    p.add_argument("--chunk", type=int, default=2_048)
    p.add_argument("--max-steps", type=int, default=200_000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--episodes", type=int, default=100, help="evaluation runs after each round (default 100)")
    p.add_argument("--out", type=Path, default=Path(tempfile.gettempdir()) / "flowtest-bench-ppo.zip", help="where the model that reached the target is saved")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override one training setting (JSON value), e.g. --set n_envs=1")
    args = p.parse_args(argv)

    from experiments.training.settings import DEFAULTS
    from experiments.training.system import make_model, make_training_vec_env, success_rate

    settings = dict(DEFAULTS)
    for item in args.set:
        key, sep, value = item.partition("=")
        if not sep or key not in DEFAULTS:
            p.error(f"--set {item!r}: expected KEY=VALUE with KEY one of {', '.join(DEFAULTS)}")
        try:
            settings[key] = json.loads(value)
        except json.JSONDecodeError:
            p.error(f"--set {item!r}: the value is not JSON")
    env = make_training_vec_env(args.env, args.seed, settings)
    model = make_model(env, settings, args.seed)
    print(f"MaskablePPO on {args.env}, seed {args.seed}, settings {settings}", flush=True)
    train_s, rate = 0.0, 0.0
    while model.num_timesteps < args.max_steps:
        t0 = time.perf_counter()
        model.learn(total_timesteps=args.chunk, reset_num_timesteps=False)
        train_s += time.perf_counter() - t0
        t1 = time.perf_counter()
        rate = success_rate(model, args.env, args.episodes)
        steps = model.num_timesteps
        print(f"{steps:7d} steps  {train_s:7.1f} s training  success {100 * rate:5.1f} % ({args.episodes} runs, {time.perf_counter() - t1:.1f} s)", flush=True)
        if rate >= args.target:
            model.save(str(args.out))
            print(f"reached {100 * rate:.0f} % after {steps} steps, {train_s:.1f} s training wall time; model {args.out}")
            return 0
    print(f"not reached: {100 * rate:.0f} % after {model.num_timesteps} steps", file=sys.stderr)
    return 1


if __name__ == "__main__":
    raise SystemExit(main())
