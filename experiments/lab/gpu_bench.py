"""Env steps per second of the NumPy vector env and the torch env (CPU, and GPU when there is one).

Usage::

    .venv/bin/python -m experiments.lab.gpu_bench --out gpu-bench.json                  # the full run (a GPU: < 5 min)
    .venv/bin/python -m experiments.lab.gpu_bench --quick --out cpu-bench.json          # small sizes, CPU only
    .venv/bin/python -m experiments.lab.gpu_bench --cases maze2-tables --sizes 1024 65536 --devices cpu

Cases, each at growing ``num_envs`` (random *masked* actions drawn on the env's own device,
``argmax(uniform * mask)``, every step; the NumPy env draws them with NumPy):

* ``maze2-tables``: ``FlowTest-Maze2-v0``'s tables stepped by the functional step, no
  observation gathered (what a trainer with its own state encoding pays);
* ``maze2-obs-visited``: the same with the float observation and the visited-places memory
  (331 float32 a step);
* ``pool-padded``: the pool ``reachability1/5x5`` (``--pool-count`` tests, 512 by default),
  padded observation (901 float32 a step);
* ``pool-compact``: the same pool, compact observation (``int64[N, 2]``: the observation
  row and the packed memory) as :mod:`flowtest_env.torch_vector` gives it.

Backends: ``numpy`` (:class:`flowtest_env.vector.PoolVectorEnv`, the Gymnasium step with
its infos), ``torch-cpu`` and ``torch-cuda`` (the functional step of
:mod:`flowtest_env.torch_vector`, same-step autoreset, no Python loop over envs). Each
measurement repeats steps until ``--seconds`` have passed (after warm-up steps), so the
run's length does not depend on the machine; a size whose tensors would not fit the device
is skipped and said so. With ``--train`` (and :mod:`agents.native_ppo` present) it also
times the native trainer end to end on the pool (its defaults: the hand-written MLP update,
the varying observation entries), and with ``--fit`` the seconds until its greedy policy
meets 95 % of ``reachability1/5x5-v2``'s first 128 train tests (the time-to-score figure of
``experiments/lab/time_to_score.py``, here on each device).

It prints a table and writes every figure with the machine's description to ``--out``
(JSON): one row per (case, backend, num_envs) with ``steps_per_s``.

The pool's tests are built on first use and cached (``FLOWTEST_CACHE_DIR``; 512 tests take
minutes of synthesis on a few cores): build them once before a timed GPU run, and carry
the cache to the GPU machine.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch

import flowtest_env  # noqa: F401  (registers the envs)
from flowtest_env import torch_vector as tv
from flowtest_env.pools import load_pool
from flowtest_env.vector import PoolVectorEnv

CASES = ("maze2-tables", "maze2-obs-visited", "pool-padded", "pool-compact")
GPU_SIZES = (1024, 16384, 262144, 1048576, 4194304)
CPU_SIZES = (256, 4096, 65536)
NUMPY_SIZES = (256, 4096, 65536)
QUICK_SIZES = (64, 1024)
POOL = "reachability1/5x5"


def machine() -> dict[str, Any]:
    """What the figures were measured on."""
    out: dict[str, Any] = {
        "python": platform.python_version(),
        "torch": torch.__version__,
        "numpy": np.__version__,
        "platform": platform.platform(),
        "cpu_count": os.cpu_count(),
        "torch_threads": torch.get_num_threads(),
        "load_average": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
    }
    if torch.cuda.is_available():
        out["gpu"] = torch.cuda.get_device_name(0)
        out["gpu_memory_gib"] = round(torch.cuda.get_device_properties(0).total_memory / 2**30, 1)
    return out


def sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def timed(step: Callable[[], Any], device: torch.device, seconds: float, warmup: int = 3) -> tuple[int, float]:
    """Run ``step`` ``warmup`` times, then repeatedly for about ``seconds``: (steps, wall seconds)."""
    for _ in range(warmup):
        step()
    sync(device)
    t0 = time.perf_counter()
    n, batch = 0, 1
    while True:
        for _ in range(batch):
            step()
        n += batch
        sync(device)
        dt = time.perf_counter() - t0
        if dt >= seconds:
            return n, dt
        batch = min(batch * 2, 256)


# ---------------------------------------------------------------- the cases


def tables_for(case: str, device: torch.device, pool_count: int) -> tuple[tv.TorchTables, PoolVectorEnv]:
    """The case's NumPy env (one env) and its tables on ``device``."""
    np_env = numpy_env(case, 1, pool_count)
    return tv.tables_of(np_env, device=device), np_env


def numpy_env(case: str, num_envs: int, pool_count: int) -> PoolVectorEnv:
    """The NumPy vector env of a case (the NumPy env always gathers the observation, so
    ``maze2-tables`` is plain ``FlowTest-Maze2-v0``)."""
    if case.startswith("maze2"):
        memory = "visited" if case == "maze2-obs-visited" else "none"
        return PoolVectorEnv(num_envs, ["maze2"], memory=memory)
    return PoolVectorEnv(num_envs, load_pool(POOL, count=pool_count), obs_kind="padded", memory="visited", max_steps=100)


def bench_torch(case: str, tables: tv.TorchTables, num_envs: int, seconds: float, compiled: bool = False) -> dict[str, Any]:
    """Steps/s of the functional step on ``tables``' device (same-step autoreset); with
    ``compiled``, the step and the observation through ``torch.compile``."""
    device = tables.device
    state = tv.reset_state(tables, num_envs, seed=0)
    gen = torch.Generator(device=device).manual_seed(0)
    holder = {"state": state}
    a_n = tables.n_actions
    observes = case in ("maze2-obs-visited", "pool-padded")
    buffer = torch.empty((num_envs, *tables.obs_shape), dtype=tables.obs.dtype, device=device) if observes else None

    def advance(s: tv.EnvState, u: torch.Tensor) -> tuple[tv.EnvState, torch.Tensor | None]:
        a = torch.argmax(u * tables.mask.index_select(0, s.z), dim=1)
        s, _ = tv.step(tables, s, a, "same_step")
        if case == "pool-compact":
            return s, tv.compact(tables, s)
        if case == "maze2-tables":
            return s, None
        return s, tv.observe(tables, s, None if compiled else buffer)  # one observation buffer, as copy=False

    fn = torch.compile(advance, dynamic=False) if compiled else advance

    def one() -> None:
        u = torch.rand((num_envs, a_n), generator=gen, device=device)
        holder["state"], _ = fn(holder["state"], u)

    n, dt = timed(one, device, seconds)
    return {"steps": n * num_envs, "seconds": dt, "steps_per_s": n * num_envs / dt}


def bench_numpy(case: str, num_envs: int, pool_count: int, seconds: float) -> dict[str, Any]:
    """Steps/s of the NumPy vector env's ``step`` (its infos included)."""
    env = numpy_env(case, num_envs, pool_count)
    rng = np.random.default_rng(0)
    _, infos = env.reset(seed=0)
    holder = {"mask": infos["action_mask"]}

    def one() -> None:
        m = holder["mask"]
        a = np.argmax(rng.random(m.shape) * m, axis=1)
        _, _, _, _, inf = env.step(a)
        holder["mask"] = inf["action_mask"]

    n, dt = timed(one, torch.device("cpu"), seconds)
    return {"steps": n * num_envs, "seconds": dt, "steps_per_s": n * num_envs / dt}


def fits(tables: tv.TorchTables, num_envs: int) -> bool:
    """Whether a batch of ``num_envs`` (state, observation, mask, a few temporaries) fits
    the device's free memory with room to spare (CPU: always)."""
    if tables.device.type != "cuda":
        return True
    per_env = 8 * 16 + tables.n_actions * 8 + 4 * int(np.prod(tables.obs_shape)) * 2
    free, _ = torch.cuda.mem_get_info(tables.device)
    return num_envs * per_env < 0.6 * free


def bench_training(device: torch.device, steps: int, num_envs: int, pool_count: int, threads: int) -> dict[str, Any] | None:
    """End-to-end steps/s of the native trainer (:mod:`agents.native_ppo`, its own env and
    defaults) on the pool, training seconds only (None without the trainer)."""
    try:
        from agents import native_ppo
    except ImportError:
        return None
    args = native_ppo.NativeArgs(
        env_kwargs={"pool": POOL, "count": pool_count},
        total_steps=steps,
        num_envs=num_envs,
        device=str(device),
        eval_every=0,
        obs_kind="padded",
        threads=threads,
    )
    result = native_ppo.train(args, progress_bar=False, evaluate_train=False)
    return {
        "steps": result.steps,
        "seconds": result.seconds,
        "steps_per_s": result.steps_per_second,
        "num_envs": num_envs,
        "settings": {
            "hidden": list(args.hidden),
            "epochs": args.update_epochs,
            "minibatches": args.num_minibatches,
            "inputs": args.inputs,
            "memory": args.memory,
        },
    }


FIT_POOL = "reachability1/5x5-v2"
"""The pool of the time-to-score figure (its first 128 train tests, shipped)."""


def bench_fit(device: torch.device, num_envs: int, threads: int, budget: int = 1_500_000, target: float = 0.95) -> dict[str, Any] | None:
    """Training seconds (evaluations excluded) until the native trainer's greedy policy meets
    ``target`` of :data:`FIT_POOL`'s first 128 train tests, evaluated every 16,384 steps
    (None without the trainer; ``seconds`` None when ``budget`` steps do not get there)."""
    try:
        from agents import native_ppo
    except ImportError:
        return None
    args = native_ppo.NativeArgs(
        env_kwargs={"pool": FIT_POOL, "split": "train", "count": 128},
        total_steps=budget,
        num_envs=num_envs,
        device=str(device),
        eval_every=16_384,
        threads=threads,
    )
    result = native_ppo.train(args, progress_bar=False, until=lambda step, rates: rates["train"]["met"] >= target)
    hit = next(((s, t) for (s, r), t in zip(result.evaluations, result.eval_times, strict=True) if r["train"]["met"] >= target), None)
    return {
        "num_envs": num_envs,
        "target": target,
        "steps": hit[0] if hit else None,
        "seconds": round(hit[1], 2) if hit else None,
        "steps_per_s": result.steps_per_second,
        "final_met": result.final["train"]["met"],
    }


# ---------------------------------------------------------------- main


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m experiments.lab.gpu_bench", description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, help="write the figures as JSON here")
    p.add_argument("--cases", nargs="+", choices=CASES, default=list(CASES))
    p.add_argument("--devices", nargs="+", default=None, help="backends: numpy, cpu, cuda (default: numpy, cpu, and cuda when there is one)")
    p.add_argument("--sizes", nargs="+", type=int, help="num_envs for the torch backends (default by device)")
    p.add_argument("--numpy-sizes", nargs="+", type=int, help="num_envs for the NumPy env")
    p.add_argument("--seconds", type=float, default=1.0, help="timed seconds per measurement")
    p.add_argument("--pool-count", type=int, default=512, help="tests of the pool cases")
    p.add_argument("--quick", action="store_true", help="small sizes, 0.3 s per figure, a 16-test pool (a check that it runs)")
    p.add_argument("--train", type=int, default=0, metavar="STEPS", help="also time the native trainer for STEPS env steps")
    p.add_argument("--fit", action="store_true", help="also time the native trainer to 95 %% greedy met on 128 train tests of " + FIT_POOL)
    p.add_argument("--threads", type=int, default=1, help="torch CPU threads (1: on a busy CPU, OpenMP's spinning threads slow small ops down)")
    p.add_argument("--compile", action="store_true", help="also time the torch step through torch.compile (first call compiles: tens of seconds)")
    a = p.parse_args(argv)
    if a.quick:
        a.seconds = min(a.seconds, 0.3)
        a.pool_count = min(a.pool_count, 16)
    devices = a.devices or ["numpy", "cpu", *(["cuda"] if torch.cuda.is_available() else [])]
    for d in devices:
        if d not in ("numpy", "cpu") and not d.startswith("cuda"):
            print(f"error: unknown backend {d!r}; expected numpy, cpu or cuda", file=sys.stderr)
            return 2
        if d.startswith("cuda") and not torch.cuda.is_available():
            print(f"error: backend {d!r} asked for, but torch sees no CUDA device", file=sys.stderr)
            return 2
    torch.set_num_threads(a.threads)
    rows: list[dict[str, Any]] = []
    t_start = time.perf_counter()
    for case in a.cases:
        for d in devices:
            if d == "numpy":
                if case == "pool-compact":  # the NumPy env has no compact observation: pool-padded is its figure
                    continue
                sizes = a.numpy_sizes or (QUICK_SIZES if a.quick else NUMPY_SIZES)
                for n in sizes:
                    r = bench_numpy(case, n, a.pool_count, a.seconds)
                    rows.append({"case": case, "backend": "numpy", "num_envs": n, **r})
                    print_row(rows[-1])
                continue
            device = torch.device(d)
            tables, _ = tables_for(case, device, a.pool_count)
            sizes = a.sizes or (QUICK_SIZES if a.quick else GPU_SIZES if device.type == "cuda" else CPU_SIZES)
            for n in sizes:
                if not fits(tables, n):
                    rows.append({"case": case, "backend": f"torch-{device.type}", "num_envs": n, "skipped": "does not fit"})
                    print_row(rows[-1])
                    continue
                for compiled in (False, True) if a.compile else (False,):
                    r = bench_torch(case, tables, n, a.seconds, compiled)
                    backend = f"torch-{device.type}" + ("-compiled" if compiled else "")
                    rows.append({"case": case, "backend": backend, "num_envs": n, **r})
                    print_row(rows[-1])
            del tables
            if device.type == "cuda":
                torch.cuda.empty_cache()
    training = []
    if a.train:
        for d in devices:
            if d == "numpy":
                continue
            t = bench_training(torch.device(d), a.train, 8192 if d.startswith("cuda") else 64, a.pool_count, a.threads)
            if t is None:
                print("(no agents.native_ppo: training not timed)")
                break
            training.append({"backend": f"torch-{d}", **t})
            print(f"training  torch-{d:<6} {t['num_envs']:>9} envs  {t['steps_per_s']:>14,.0f} steps/s")
    fit_rows = []
    if a.fit:
        for d in devices:
            if d == "numpy":
                continue
            f = bench_fit(torch.device(d), 1024 if d.startswith("cuda") else 128, a.threads)
            if f is None:
                print("(no agents.native_ppo: time to score not measured)")
                break
            fit_rows.append({"backend": f"torch-{d}", **f})
            print(
                f"fit       torch-{d:<6} {f['num_envs']:>9} envs  {f['seconds']} s to {100 * f['target']:.0f} % ({f['steps']} steps, "
                f"{f['steps_per_s']:,.0f} steps/s)"
            )
    doc = {
        "command": "python -m experiments.lab.gpu_bench " + " ".join(argv if argv is not None else sys.argv[1:]),
        "machine": machine(),
        "pool": POOL,
        "pool_count": a.pool_count,
        "seconds_per_figure": a.seconds,
        "rows": rows,
        "training": training,
        "fit": fit_rows,
        "wall_seconds": round(time.perf_counter() - t_start, 1),
    }
    if a.out:
        a.out.write_text(json.dumps(doc, indent=1) + "\n")
    return 0


def print_row(r: dict[str, Any]) -> None:
    if "skipped" in r:
        print(f"{r['case']:<18} {r['backend']:<20} {r['num_envs']:>9} envs  skipped: {r['skipped']}", flush=True)
        return
    print(f"{r['case']:<18} {r['backend']:<20} {r['num_envs']:>9} envs  {r['steps_per_s']:>14,.0f} steps/s", flush=True)


if __name__ == "__main__":
    raise SystemExit(main())
