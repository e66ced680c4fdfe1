"""The learned baseline under each place memory, side by side: does a greedy policy still end
its failed runs in a loop, and what does each memory score held out?

    python -m experiments.lab.memory_baselines --seeds 0 1 2 --out memory.json

For each seed and each ``--memories`` kind (``visited``, ``counts``; interleaved, so that the
machine's load falls on both alike) the native trainer with ``flowtest train``'s settings
(``--native-set KEY=VALUE`` changes one) trains on the first ``--train-count`` train tests of
``--pool`` for ``--steps``, evaluating the greedy policy on the ``validation`` split every
``--eval-every`` steps: that curve shows the plateau, and the checkpoint kept is the one with
the best validation met (:func:`agents.native_ppo.train`'s ``validation``). The kept policy is
then scored on the first ``--test-count`` held-out tests (the ``test`` split) greedily (each
test once) and sampled (``--runs`` seeded runs a test), and normalized as the protocol does,
``(met - floor) / (ceiling - floor)``, with the random floor measured here and the reference
ceiling ``--ceiling`` (1.0 on the continuity pool, docs/pools.md).

**Loops.** Every greedy run that fails is checked for the loop issue 41 describes: its last
observations repeat with period 2 (the SUT steps back and forth between two cells and the
env shows the same thing each time), read from fingerprints of the observations the policy
was shown.

Prints a table and writes every curve, score, the command, the machine and the load before
and after as JSON (``--out``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from experiments.lab.time_to_score import load_now, machine, native_overrides

POOL_ENV_ID = "FlowTest-RandomGrid-v0"


class Fingerprints:
    """A batched policy that records a fingerprint of every row's observation at every step
    (a random projection, float64), then asks ``policy``."""

    def __init__(self, policy: Any, width: int) -> None:
        self.policy = policy
        self.proj = np.random.default_rng(12345).standard_normal(width)
        self.seen: list[np.ndarray] = []

    def reset(self, n: int, seed: int) -> None:
        self.seen = []
        self.policy.reset(n, seed)

    def __call__(self, obs: np.ndarray, masks: np.ndarray) -> np.ndarray:
        self.seen.append(np.asarray(obs, dtype=np.float64).reshape(len(obs), -1) @ self.proj)
        out: np.ndarray = self.policy(obs, masks)
        return out


def loops(prints: Sequence[np.ndarray], steps: np.ndarray, failed: np.ndarray) -> int:
    """How many of the ``failed`` runs end with their observation repeating every second
    step (``obs[s-1] == obs[s-3]`` and ``obs[s-2] == obs[s-4]``, ``s`` the run's steps)."""
    fp = np.stack(prints)  # [steps, runs]
    count = 0
    for i in np.flatnonzero(failed):
        s = int(steps[i])
        if s >= 4 and fp[s - 1, i] == fp[s - 3, i] and fp[s - 2, i] == fp[s - 4, i]:
            count += 1
    return count


def score(model: Any, memory: str, games: list[Any], runs: int, floor: float, ceiling: float) -> dict[str, Any]:
    """Greedy (one run a test) and sampled (``runs`` a test) held-out met, normalized; the
    greedy failures and how many of them end in a loop."""
    from agents.native.evaluation import BatchActor
    from flowtest_env.scoring import play_batch

    agent, where = model
    out: dict[str, Any] = {}
    for mode, k in (("greedy", 1), ("sampled", runs)):
        policy = Fingerprints(BatchActor(agent, where, mode == "greedy", memory=memory), agent.obs_size - (where.stop - where.start))
        v = play_batch(policy, games, runs=k, seed=0)
        met = v["system_objective"] == "met"
        out[mode] = {"met": float(met.mean()), "normalized": float((met.mean() - floor) / (ceiling - floor)), "runs": int(met.size)}
        if mode == "greedy":
            failed = ~met.reshape(-1)
            out[mode]["failures"] = int(failed.sum())
            out[mode]["failures_in_a_loop"] = loops(policy.seen, v["steps"].reshape(-1), failed)
    return out


def parse(argv: Sequence[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pool", default="reachability1/5x5-v2")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--memories", nargs="+", choices=("visited", "counts"), default=["visited", "counts"])
    ap.add_argument("--steps", type=int, default=2_000_000)
    ap.add_argument("--eval-every", type=int, default=131_072)
    ap.add_argument("--train-count", type=int, default=4096)
    ap.add_argument("--validation-count", type=int, default=256)
    ap.add_argument("--test-count", type=int, default=1000)
    ap.add_argument("--runs", type=int, default=8)
    ap.add_argument("--ceiling", type=float, default=1.0)
    ap.add_argument("--native-set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--out", type=Path, default=None)
    return ap.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    a = parse(argv)
    import torch

    from agents.native_ppo import train
    from experiments.training.settings import native_args, native_settings
    from flowtest_env.game import TestGame
    from flowtest_env.pools import load_pool
    from flowtest_env.scoring import random_policy, score_policy

    torch.set_num_threads(1)
    doc: dict[str, Any] = {
        "command": " ".join([sys.executable, "-m", "experiments.lab.memory_baselines", *(argv or sys.argv[1:])]),
        "machine": machine(),
        "load_before": load_now(),
        "runs": [],
    }
    validation = [TestGame(x) for x in load_pool(a.pool, "validation", a.validation_count)]
    held = [TestGame(x) for x in load_pool(a.pool, "test", a.test_count)]
    floor = float(score_policy(random_policy(), tests=held, runs=a.runs, seed=0).met)
    doc["floor"], doc["ceiling"] = floor, a.ceiling
    t0 = time.perf_counter()
    for seed in a.seeds:
        for memory in a.memories:
            settings = native_settings({**native_overrides(a.native_set), "memory": memory})
            args = native_args(settings, POOL_ENV_ID, {"pool": a.pool, "split": "train", "count": a.train_count}, a.steps, seed, eval_every=a.eval_every)
            wall = time.perf_counter()
            result = train(args, validation=validation, progress_bar=False, evaluate_train=256)
            pos = result.settings["position"]
            scores = score((result.agent, slice(int(pos[0]), int(pos[1]))), memory, held, a.runs, floor, a.ceiling)
            row = {
                "seed": seed,
                "memory": memory,
                "steps": result.steps,
                "seconds": round(result.seconds, 1),
                "steps_per_second": round(result.steps_per_second, 1),
                "wall_seconds": round(time.perf_counter() - wall, 1),
                "selected_step": result.selected_step,
                "curve": [[s, r.get("train", {}).get("met"), r["validation"]["met"]] for s, r in result.evaluations],
                "heldout": scores,
                "settings": settings,
            }
            doc["runs"].append(row)
            g, s = scores["greedy"], scores["sampled"]
            print(
                f"[{time.perf_counter() - t0:6.0f} s] seed {seed} {memory:8s}: {result.steps} steps in {result.seconds:.0f} s, kept step "
                f"{result.selected_step}; held-out greedy {100 * g['met']:.1f} % ({g['normalized']:+.2f}), sampled {100 * s['met']:.1f} % "
                f"({s['normalized']:+.2f}); greedy failures {g['failures']}, in a loop {g['failures_in_a_loop']}; load {load_now()}",
                file=sys.stderr,
                flush=True,
            )
            if a.out is not None:
                a.out.write_text(json.dumps(doc, indent=1) + "\n")
    doc["load_after"] = load_now()
    doc["wall_seconds"] = round(time.perf_counter() - t0, 1)
    for memory in a.memories:
        rows = [r for r in doc["runs"] if r["memory"] == memory]
        for mode in ("greedy", "sampled"):
            vals = [r["heldout"][mode]["normalized"] for r in rows]
            mets = [r["heldout"][mode]["met"] for r in rows]
            print(
                f"{memory:8s} {mode:8s} held-out met {100 * np.mean(mets):.1f} % (seeds: {[round(100 * m, 1) for m in mets]}), normalized {np.mean(vals):+.3f}"
            )
        fails = sum(r["heldout"]["greedy"]["failures"] for r in rows)
        looped = sum(r["heldout"]["greedy"]["failures_in_a_loop"] for r in rows)
        print(f"{memory:8s} greedy failures ending in a two-step loop: {looped} of {fails}")
    if a.out is not None:
        a.out.write_text(json.dumps(doc, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
