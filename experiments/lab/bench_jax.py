"""FlowTest's vector env against JAX environments under ``jit`` (gymnax, xminigrid), side by
side in one run on the same cores.

Usage::

    # the JAX side lives in a throwaway venv, never in the project's lock
    python3 -m venv /tmp/jaxvenv
    /tmp/jaxvenv/bin/pip install jax jaxlib gymnax xminigrid six gymnasium==1.4.0
    .venv/bin/python experiments/lab/bench_jax.py --jax-python /tmp/jaxvenv/bin/python \\
        [--envs 1024 16384] [--seconds 1.5] [--repeat 5] [--gymnasium] [--before DIR] [--out FILE] [--json FILE]

Every row steps a batch of ``--envs`` envs with uniformly random actions drawn each batch step
(FlowTest: NumPy's generator in the timed loop; JAX: ``jax.random`` inside the jitted step)
and autoreset (FlowTest: Gymnasium's next-step autoreset; gymnax and xminigrid reset within
the step), and counts env steps the same way for every row: batch steps x envs. The rows:

* FlowTest's NumPy vector env (``gym.make_vec(..., vectorization_mode="vector_entry_point")``)
  on ``FlowTest-Maze2-v0`` (a 5x5 maze with a test agent) with the flat observation
  (``float32[306]``; and ``uint8[306]``, the same 0/1 entries, with ``obs_dtype="uint8"``) and
  the grid one (``uint8[14, 5, 5]``), and on 64 tests of the standard
  pool ``reachability1/5x5-v2`` with the padded observation (``float32[901]``, each episode
  draws its test; also with ``copy=False``, one output buffer, and with ``obs_dtype="uint8"``);
* FlowTest's torch env on the CPU (:mod:`flowtest_env.torch_vector`, one torch thread) on
  Maze 2, flat and grid;
* gymnax ``FourRooms-misc`` (its default observation, ``float32[4]``: the agent's and the
  goal's cells) and xminigrid ``MiniGrid-FourRooms`` (``uint8[7, 7, 2]``, with its
  ``GymAutoResetWrapper``), both ``jax.jit(jax.vmap(step))``, each two ways: a Python loop of
  jitted batch steps whose outputs are returned (as FlowTest's loop is), and one
  ``jax.lax.scan`` over all the run's batch steps (the fused form, every observation summed
  into the carry so that none is optimised away).

``--before DIR`` adds the FlowTest rows of an older checkout (``git worktree add DIR <commit>``
or ``git archive <commit> | tar -x -C DIR``), run by this Python with ``DIR`` first on its
path, so that the speed-up is measured in the same run too.

The JAX rows run in a worker process of ``--jax-python`` (this file, ``--worker``), started
once and compiled before any timing (each row is warmed up and calibrated first); the rows
are measured round-robin, ``--repeat`` rounds, so every row sees the same load; each run
lasts about ``--seconds``. Reported: the median and best steps per second over the rounds,
the cores each row used (process CPU seconds over wall seconds: JAX's CPU backend runs on
several threads, NumPy on one), and each row's median over gymnax's (the faster of its
two forms). ``--gymnasium`` adds Gymnasium's own neutral measure,
``gymnasium.utils.performance.benchmark_vector_step`` (random ``action_space.sample()``
actions; with next-step autoreset it does not count the reset steps), on FlowTest's NumPy
env and, in the worker, on gymnax's ``GymnaxToVectorGymWrapper``. The 1-minute load average
is printed before and after.

This file must run under the throwaway venv's Python as a worker, which has neither
FlowTest nor the project on its path: it imports nothing of FlowTest at module level.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

Runner = Callable[[int], None]
"""``run(batch_steps)``: step a prepared batch that many times."""


def _timed(run: Runner, steps: int) -> tuple[float, float]:
    """Wall and process CPU seconds of ``run(steps)``."""
    t, c = time.perf_counter(), time.process_time()
    run(steps)
    return time.perf_counter() - t, time.process_time() - c


def _calibrate(run: Runner, seconds: float) -> int:
    """Batch steps for a run of about ``seconds`` (after a warm-up run)."""
    run(3)
    steps = 3
    while True:
        wall, _ = _timed(run, steps)
        if wall >= 0.2 * seconds or steps >= 1 << 20:
            return max(3, int(steps * seconds / max(wall, 1e-9)))
        steps *= 4


# ------------------------------------------------------------------ the JAX worker


def _jax_rows(name: str, n: int) -> tuple[Runner, str]:
    """A prepared JAX row (compiled, state kept between runs) and its observation."""
    jax = importlib.import_module("jax")
    jnp = importlib.import_module("jax.numpy")
    if name.startswith("gymnax"):
        gymnax = importlib.import_module("gymnax")
        env, params = gymnax.make("FourRooms-misc")
        n_actions = int(env.action_space(params).n)
        vstep = jax.vmap(env.step, in_axes=(0, 0, 0, None))
        key = jax.random.key(0)
        _, state = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(key, n), params)
        obs_kind = "float32[4]"

        def one(state: Any, key: Any) -> tuple[Any, Any, Any]:
            key, ka, ks = jax.random.split(key, 3)
            a = jax.random.randint(ka, (n,), 0, n_actions)
            obs, state, r, term, trunc, _ = vstep(jax.random.split(ks, n), state, a, params)
            return state, key, (obs, r, term, trunc)
    else:
        xminigrid = importlib.import_module("xminigrid")
        xenv, params = xminigrid.make("MiniGrid-FourRooms")
        xenv = importlib.import_module("xminigrid.wrappers").GymAutoResetWrapper(xenv)
        n_actions = int(xenv.num_actions(params))
        key = jax.random.key(0)
        state = jax.vmap(xenv.reset, in_axes=(None, 0))(params, jax.random.split(key, n))
        xstep = jax.vmap(xenv.step, in_axes=(None, 0, 0))
        obs_kind = "uint8[7, 7, 2]"

        def one(state: Any, key: Any) -> tuple[Any, Any, Any]:
            key, ka = jax.random.split(key)
            a = jax.random.randint(ka, (n,), 0, n_actions)
            ts = xstep(params, state, a)
            return ts, key, (ts.observation, ts.reward, ts.step_type, ts.discount)

    carry: dict[str, Any] = {"state": state, "key": key}
    if name.endswith("loop"):
        step = jax.jit(one)

        def run(steps: int) -> None:
            s, k = carry["state"], carry["key"]
            out: Any = None
            for _ in range(steps):
                s, k, out = step(s, k)
            jax.block_until_ready(out)
            carry["state"], carry["key"] = s, k

        return run, obs_kind

    compiled: dict[int, Any] = {}

    def scanned(steps: int) -> Any:
        def body(c: Any, _: Any) -> tuple[Any, None]:
            s, k, acc = c
            s, k, out = one(s, k)
            acc = acc + sum(jnp.sum(x.astype(jnp.float32)) for x in out)
            return (s, k, acc), None

        def many(s: Any, k: Any) -> Any:
            return jax.lax.scan(body, (s, k, jnp.float32(0)), None, length=steps)[0]

        return jax.jit(many)

    def run_scan(steps: int) -> None:
        if steps not in compiled:
            compiled[steps] = scanned(steps)
            jax.block_until_ready(compiled[steps](carry["state"], carry["key"]))  # compile outside the timing
        s, k, acc = compiled[steps](carry["state"], carry["key"])
        jax.block_until_ready(acc)
        carry["state"], carry["key"] = s, k

    return run_scan, obs_kind


def _gymnasium_gymnax(n: int, seconds: float) -> float:
    """``benchmark_vector_step`` of gymnax FourRooms through its Gymnasium vector wrapper."""
    from gymnasium.utils.performance import benchmark_vector_step

    env, params = importlib.import_module("gymnax").make("FourRooms-misc")
    wrapped = importlib.import_module("gymnax.wrappers.gym").GymnaxToVectorGymWrapper(env, num_envs=n, params=params, seed=0)
    return float(benchmark_vector_step(wrapped, target_duration=_whole(seconds), seed=0))


def _whole(seconds: float) -> int:
    """``benchmark_vector_step``'s duration: whole seconds."""
    return max(1, round(seconds))


def worker() -> int:
    """A worker: the JAX rows (in the throwaway venv) or the FlowTest rows of the checkout on
    its ``PYTHONPATH`` (``--before``); JSON requests on stdin, one JSON answer a line on
    stdout."""
    rows: dict[tuple[str, int], tuple[Runner, int]] = {}
    for line in sys.stdin:
        req = json.loads(line)
        op, name, n = req["op"], req.get("row", ""), int(req.get("envs", 0))
        try:
            if op == "versions":
                from importlib import metadata

                ans: dict[str, Any] = {p: metadata.version(p) for p in req["packages"]}
                if req.get("flowtest"):
                    ans["flowtest_env"] = str(Path(importlib.import_module("flowtest_env").__file__ or "").parent)
            elif op == "prepare":
                run, obs_kind = _jax_rows(name, n) if name in JAX_ROWS else _flowtest_row(name, n)
                steps = _calibrate(run, float(req["seconds"]))
                run(steps)  # the scan form compiles for this length here
                rows[(name, n)] = (run, steps)
                ans = {"obs": obs_kind, "steps": steps}
            elif op == "run":
                run, steps = rows[(name, n)]
                wall, cpu = _timed(run, steps)
                ans = {"rate": steps * n / wall, "cores": cpu / wall}
            elif op == "gymnasium":
                ans = {"rate": _gymnasium_gymnax(n, float(req["seconds"]))}
            else:
                ans = {"error": f"unknown request {op!r}"}
        except Exception as exc:  # reported to the parent, which says so
            ans = {"error": f"{type(exc).__name__}: {exc}"}
        print(json.dumps(ans), flush=True)
    return 0


class Worker:
    """A worker process (:func:`worker`): ``python`` running this file, with ``path`` first
    on its ``PYTHONPATH`` when given (a checkout to measure)."""

    def __init__(self, python: str, path: str | None = None) -> None:
        env = {**os.environ, "JAX_PLATFORMS": "cpu"}
        if path is not None:
            env["PYTHONPATH"] = os.pathsep.join([path, *filter(None, [os.environ.get("PYTHONPATH")])])
        self.proc = subprocess.Popen(
            [python, str(Path(__file__).resolve()), "--worker"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            env=env,
        )

    def ask(self, **req: Any) -> dict[str, Any]:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write(json.dumps(req) + "\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError(f"the JAX worker stopped (exit {self.proc.poll()})")
        ans: dict[str, Any] = json.loads(line)
        return ans

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()


# ------------------------------------------------------------------ FlowTest's rows


def _flowtest_row(name: str, n: int) -> tuple[Runner, str]:
    """A prepared FlowTest row (``"<numpy|pool|torch> <obs_kind>[-uint8][-nocopy]"``) and
    its observation."""
    import gymnasium as gym
    import numpy as np

    import flowtest_env  # noqa: F401 - registers the IDs

    rng = np.random.default_rng(0)
    kind, *flags = name.split()[-1].split("-")
    extra: dict[str, Any] = {"obs_dtype": "uint8"} if "uint8" in flags else {}  # only where asked: an older checkout has neither
    if "nocopy" in flags:
        extra["copy"] = False
    if name.startswith("torch"):
        import torch

        from flowtest_env.torch_vector import make_vec

        torch.set_num_threads(1)
        tenv = make_vec("FlowTest-Maze2-v0", n, obs_kind=kind)
        obs, _ = tenv.reset(seed=0)
        gen = torch.Generator().manual_seed(0)
        space = tenv.single_action_space
        assert isinstance(space, gym.spaces.Discrete)
        n_actions = int(space.n)

        def run_torch(steps: int) -> None:
            for _ in range(steps):
                tenv.step(torch.randint(0, n_actions, (n,), generator=gen))

        return run_torch, f"{str(obs.dtype).replace('torch.', '')}{list(obs.shape[1:])}"
    if name.startswith("pool"):
        from flowtest_env.pools import load_pool
        from flowtest_env.vector import PoolVectorEnv

        env: Any = PoolVectorEnv(n, load_pool("reachability1/5x5-v2", "train", 64), obs_kind=kind, **extra)
    else:
        env = gym.make_vec("FlowTest-Maze2-v0", n, vectorization_mode="vector_entry_point", obs_kind=kind, **extra)
    obs, _ = env.reset(seed=0)
    n_actions = int(env.single_action_space.n)

    def run(steps: int) -> None:
        for _ in range(steps):
            env.step(rng.integers(0, n_actions, size=n, dtype=np.uint8))

    return run, f"{obs.dtype}{list(obs.shape[1:])}"


FLOWTEST_ROWS = ("numpy flat", "numpy flat-uint8", "numpy grid", "pool padded", "pool padded-nocopy", "pool padded-uint8", "torch flat", "torch grid")
JAX_ROWS = ("gymnax loop", "gymnax scan", "xminigrid loop", "xminigrid scan")
LABELS = {
    "numpy flat": "FlowTest NumPy vector env, `FlowTest-Maze2-v0` flat",
    "numpy flat-uint8": 'FlowTest NumPy vector env, `FlowTest-Maze2-v0` flat, `obs_dtype="uint8"`',
    "numpy grid": "FlowTest NumPy vector env, `FlowTest-Maze2-v0` grid",
    "pool padded": "FlowTest NumPy vector env, 64 tests of `reachability1/5x5-v2`, padded",
    "pool padded-nocopy": "FlowTest NumPy vector env, 64 tests of `reachability1/5x5-v2`, padded, `copy=False`",
    "pool padded-uint8": 'FlowTest NumPy vector env, 64 tests of `reachability1/5x5-v2`, padded, `obs_dtype="uint8"`',
    "torch flat": "FlowTest torch env (CPU, 1 thread), `FlowTest-Maze2-v0` flat",
    "torch grid": "FlowTest torch env (CPU, 1 thread), `FlowTest-Maze2-v0` grid",
    "gymnax loop": "gymnax `FourRooms-misc`, Python loop of jitted batch steps",
    "gymnax scan": "gymnax `FourRooms-misc`, one `lax.scan` a run",
    "xminigrid loop": "xminigrid `MiniGrid-FourRooms`, Python loop of jitted batch steps",
    "xminigrid scan": "xminigrid `MiniGrid-FourRooms`, one `lax.scan` a run",
}


def _gymnasium_flowtest(kind: str, n: int, seconds: float) -> float:
    import gymnasium as gym
    from gymnasium.utils.performance import benchmark_vector_step

    import flowtest_env  # noqa: F401

    env = gym.make_vec("FlowTest-Maze2-v0", n, vectorization_mode="vector_entry_point", obs_kind=kind)
    return float(benchmark_vector_step(env, target_duration=_whole(seconds), seed=0))


def _load() -> float:
    return os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


BEFORE = "before: "
"""Prefix of a row measured on the ``--before`` checkout."""


def measure(args: argparse.Namespace) -> dict[str, Any]:
    """Every row at every batch size, round-robin; the figures as a dict."""
    import gymnasium as gym
    import numpy as np

    load_before = _load()
    workers: dict[str, Worker] = {}
    try:
        if args.jax_python:
            workers["jax"] = Worker(args.jax_python)
        if args.before:
            workers["before"] = Worker(sys.executable, args.before)
        versions: dict[str, Any] = {"python": platform.python_version(), "numpy": np.__version__, "gymnasium": gym.__version__}
        if "jax" in workers:
            versions["jax side"] = workers["jax"].ask(op="versions", packages=["jax", "jaxlib", "gymnax", "xminigrid", "gymnasium"])
        if "before" in workers:
            versions["before"] = workers["before"].ask(op="versions", packages=[], flowtest=True)
        ours = [r for r in FLOWTEST_ROWS if r in args.rows]
        rows = ours + [BEFORE + r for r in ours if "before" in workers and "-" not in r]  # an older checkout has neither option
        rows += [r for r in JAX_ROWS if r in args.rows and "jax" in workers]

        def worker_of(row: str) -> Worker | None:
            return workers["jax"] if row in JAX_ROWS else workers["before"] if row.startswith(BEFORE) else None

        prepared: dict[tuple[str, int], tuple[Runner | None, int, str]] = {}
        for n in args.envs:
            for r in rows:
                print(f"preparing {r} at {n} envs", file=sys.stderr, flush=True)
                w = worker_of(r)
                if w is not None:
                    ans = w.ask(op="prepare", row=r.removeprefix(BEFORE), envs=n, seconds=args.seconds)
                    if "error" in ans:
                        print(f"  skipped: {ans['error']}", file=sys.stderr)
                        continue
                    prepared[(r, n)] = (None, int(ans["steps"]), str(ans["obs"]))
                else:
                    run, obs = _flowtest_row(r, n)
                    prepared[(r, n)] = (run, _calibrate(run, args.seconds), obs)
        results: dict[tuple[str, int], list[tuple[float, float]]] = {k: [] for k in prepared}
        for rnd in range(args.repeat):
            for (r, n), (prepared_run, steps, _) in prepared.items():
                w = worker_of(r)
                if prepared_run is None:
                    assert w is not None
                    ans = w.ask(op="run", row=r.removeprefix(BEFORE), envs=n)
                    rate, cores = float(ans["rate"]), float(ans["cores"])
                else:
                    wall, cpu = _timed(prepared_run, steps)
                    rate, cores = steps * n / wall, cpu / wall
                results[(r, n)].append((rate, cores))
                print(f"round {rnd + 1}/{args.repeat}: {r} at {n} envs: {rate / 1e6:.2f}M steps/s ({cores:.2f} cores)", file=sys.stderr, flush=True)
        neutral: dict[str, float] = {}
        if args.gymnasium:
            for n in args.envs:
                for kind in ("flat", "grid"):
                    neutral[f"FlowTest Maze2 {kind} at {n}"] = _gymnasium_flowtest(kind, n, args.seconds)
                if "jax" in workers:
                    ans = workers["jax"].ask(op="gymnasium", envs=n, seconds=args.seconds)
                    if "rate" in ans:
                        neutral[f"gymnax FourRooms at {n}"] = float(ans["rate"])
    finally:
        for w in workers.values():
            w.close()
    return {
        "machine": f"{_cpu_model()}, {os.cpu_count()} cores, {platform.machine()}",
        "versions": versions,
        "before": args.before,
        "load_before": load_before,
        "load_after": _load(),
        "seconds": args.seconds,
        "repeat": args.repeat,
        "rows": [
            {
                "row": r,
                "label": LABELS[r] if r in LABELS else f"{LABELS[r.removeprefix(BEFORE)]}, before ({args.before})",
                "envs": n,
                "obs": prepared[(r, n)][2],
                "batch_steps": prepared[(r, n)][1],
                "rates": [x for x, _ in res],
                "cores": [c for _, c in res],
            }
            for (r, n), res in results.items()
        ],
        "gymnasium_benchmark_vector_step": neutral,
    }


def markdown(fig: dict[str, Any]) -> str:
    """The figures as Markdown tables, one per batch size."""
    lines = [
        f"Machine: {fig['machine']}; {json.dumps(fig['versions'])}; {fig['repeat']} rounds of about {fig['seconds']} s a run; "
        f"1-min load average {fig['load_before']:.2f} before, {fig['load_after']:.2f} after.",
        "",
    ]
    for n in sorted({r["envs"] for r in fig["rows"]}):
        rows = [r for r in fig["rows"] if r["envs"] == n]
        jax_bar = max((statistics.median(r["rates"]) for r in rows if r["row"].startswith("gymnax")), default=float("nan"))
        lines += [
            f"**{n:,} envs**",
            "",
            "| row | observation | median steps/s | best steps/s | cores used | median / gymnax |",
            "| --- | --- | ---: | ---: | ---: | ---: |",
        ]
        for r in rows:
            med = statistics.median(r["rates"])
            ratio = f"{med / jax_bar:.2f}x" if jax_bar == jax_bar else "-"  # nan: no gymnax row
            lines.append(f"| {r['label']} | `{r['obs']}` | {med:,.0f} | {max(r['rates']):,.0f} | {statistics.median(r['cores']):.2f} | {ratio} |")
        lines.append("")
    if fig["gymnasium_benchmark_vector_step"]:
        lines += ["Gymnasium's `benchmark_vector_step`:", ""]
        lines += [f"- {k}: {v:,.0f} steps/s" for k, v in fig["gymnasium_benchmark_vector_step"].items()]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--jax-python", help="the throwaway venv's Python with jax, gymnax and xminigrid (none: FlowTest rows only)")
    ap.add_argument("--envs", type=int, nargs="+", default=[1024, 16384], help="batch sizes")
    ap.add_argument("--seconds", type=float, default=1.5, help="about this long a run")
    ap.add_argument("--repeat", type=int, default=5, help="rounds (median and best reported)")
    ap.add_argument(
        "--rows",
        nargs="+",
        default=[*FLOWTEST_ROWS, *JAX_ROWS],
        choices=[*FLOWTEST_ROWS, *JAX_ROWS],
        metavar="ROW",
        help=f"rows to measure (default all: {', '.join(FLOWTEST_ROWS + JAX_ROWS)})",
    )
    ap.add_argument("--gymnasium", action="store_true", help="also Gymnasium's benchmark_vector_step on both sides")
    ap.add_argument("--before", metavar="DIR", help="also the FlowTest rows of the checkout in DIR (an older commit), in a worker process")
    ap.add_argument("--out", help="also write the Markdown here")
    ap.add_argument("--json", help="also write the figures as JSON here")
    args = ap.parse_args(argv)
    if args.worker:
        return worker()
    if min(args.envs) < 1 or args.repeat < 1 or args.seconds <= 0:
        print("error: --envs and --repeat must be at least 1 and --seconds positive", file=sys.stderr)
        return 2
    if args.before and not (Path(args.before) / "flowtest_env" / "vector.py").is_file():
        print(f"error: --before {args.before}: not a FlowTest checkout (no flowtest_env/vector.py)", file=sys.stderr)
        return 2
    if args.jax_python and not Path(args.jax_python).is_file():
        print(f"error: --jax-python {args.jax_python}: no such file (make the throwaway venv first: see the module docstring)", file=sys.stderr)
        return 2
    try:
        fig = measure(args)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    text = markdown(fig)
    print(text)
    if args.out:
        Path(args.out).write_text(text)
    if args.json:
        Path(args.json).write_text(json.dumps(fig, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
