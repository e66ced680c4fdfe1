"""Learned testers against synthesized tests: train, compare, check, draw.

1. Trains a learned tester (``flowtest train-tester``, MaskablePPO against the correct
   ``scripted:replanner``) on every test-agent and reactive-door problem, seeded, into
   ``OUT/testers/<problem>.zip``, and checks each exhaustively
   (:func:`flowtest_env.fairness.check_tester`).
2. Trains a PPO system under test (``flowtest train``) on each compared env.
3. Runs ``flowtest evaluate --tester synthesized ppo:OUT/testers`` on each compared env
   with the correct, faulty, GR(1), random and PPO systems (one report per env in
   ``OUT/evaluate-<env>/``) and prints the side-by-side table (``OUT/comparison.md``).
4. Draws the exhaustive search's shortest witnesses against each learned tester: into a
   trap (then the correct replanner trying from there) and to the goal without the test
   objective, with the replanner's run against the synthesized test of the same problem
   (``--figures``).

``--seeds 0 1 2`` instead trains a tester per problem and seed and tabulates only the
exhaustive checks (trap states, bypass moves).

Run: ``nice python -m experiments.lab.bench_testers`` (about ten minutes on one core).
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Any

PROBLEMS = ["maze1", "maze2", "patrolling", "small-reactive", "beaver-rescue", "motion-primitives"]
COMPARED = ["FlowTest-Maze2-v0", "FlowTest-SmallReactive-v0", "FlowTest-BeaverRescue-v0", "FlowTest-MotionPrimitives-v0"]
SUTS = ["scripted:replanner", "gr1", "scripted:committed", "scripted:fuel-blind", "scripted:greedy", "random"]


def witness_trace(problem: str, tester: str, env_id: str, kind: str = "trap", extra_steps: int = 20) -> Any:
    """A :class:`experiments.evaluation.episodes.Trace` of the exhaustive search's shortest witness
    against ``tester``: into its first trap (``kind="trap"``; then the correct replanner
    tries for ``extra_steps`` steps from there), or a run that meets the system objective
    without the test objective (``kind="bypass"``). ``None`` if there is no such run."""
    from agents.registry import make_policy
    from agents.testers import VersusTesterEnv
    from experiments.evaluation.episodes import Trace
    from flowtest_env.fairness import check_tester

    env = VersusTesterEnv(problem, tester, max_steps=10_000)
    report = check_tester(env.ma, env.tester)
    path = report.trap_path if kind == "trap" else report.bypass_path
    if path is None:
        return None
    label = "witness moves" + (", then scripted:replanner" if kind == "trap" else "")
    trace = Trace(env_id, label, 0, tester="learned")
    obs, info = env.reset(seed=0)
    trace.states.append(env.run.copy())
    for a in path:
        obs, _, _, _, info = env.step(a)
        trace.actions.append(a)
        trace.states.append(env.run.copy())
    if kind == "trap":
        policy = make_policy("scripted:replanner", env)
        policy.reset(0)
        for _ in range(extra_steps):
            obs, _, term, trunc, info = env.step(policy.act(obs, info))
            trace.states.append(env.run.copy())
            if term or trunc:
                break
        trace.kind, trace.reason = ("trap", "trapped") if env.trapped() else ("pass", "")
    trace.verdict = env.game.verdict(env.run)
    return trace


def draw(out: Path, figures: Path | None, seed: int) -> None:
    """Pictures of every learned tester's shortest trap and bypass witnesses, with the
    correct replanner's run against the synthesized test of the same problem."""
    import flowtest_env
    from agents.testers import problem_of
    from experiments.evaluation.episodes import make_tester_env, run_episode, sut_policy
    from experiments.evaluation.trace_picture import trace_picture

    tester = f"ppo:{out / 'testers'}"
    for problem in PROBLEMS:
        env_id = next(e for e in flowtest_env.ENV_IDS if e != "FlowTest-RandomGrid-v0" and problem_of(e)[0] == problem)
        drawn = []
        for kind in ("trap", "bypass"):
            trace = witness_trace(problem, tester, env_id, kind)
            if trace is None:
                continue
            png = out / f"{kind}-{problem}.png"
            trace_picture(trace, png)
            drawn.append(png)
            print(f"{problem}: {kind} witness of {len(trace.actions)} system moves; picture {png}", flush=True)
        if not drawn:
            continue
        env = make_tester_env(env_id, "synthesized")
        syn = run_episode(env, sut_policy("scripted:replanner", env), env_id, "scripted:replanner", seed)
        png = out / f"synthesized-{problem}.png"
        trace_picture(syn, png)
        drawn.append(png)
        if figures is not None:
            figures.mkdir(parents=True, exist_ok=True)
            for png in drawn:
                shutil.copy(png, figures / f"learned-tester-{png.name}")


def seed_study(out: Path, seeds: list[int], steps: int, trap_penalty: float = 0.0) -> str:
    """Train a tester per problem and seed (no evaluation) and tabulate the exhaustive
    checks: how much of what a learned tester is depends on its seed."""
    from experiments.training.tester import train_tester

    lines = ["| problem | " + " | ".join(f"seed {s}: trap states / bypass moves" for s in seeds) + " |", "|---|" + "---|" * len(seeds)]
    for problem in PROBLEMS:
        cells = []
        for seed in seeds:
            s = train_tester(problem, steps, out / f"seed{seed}" / f"{problem}.zip", seed=seed, progress_bar=False, eval_episodes=0, trap_penalty=trap_penalty)
            f = s["fairness"]
            cells.append(f"{f['traps']} / {f['bypasses']} (of {f['nodes']})")
            print(f"{problem} seed {seed}: {cells[-1]}", flush=True)
        lines.append(f"| {problem} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument(
        "--out",
        type=Path,
        default=Path(tempfile.gettempdir()) / "flowtest-bench-testers",
        help="where models, reports and pictures go (default: the temporary folder)",
    )
    p.add_argument("--steps", type=int, default=20_480, help="tester training steps per problem (default 20480)")
    p.add_argument("--sut-steps", type=int, default=16_384, help="PPO system training steps per env (default 16384)")
    p.add_argument("--episodes", type=int, default=20, help="runs per system, tester and env (default 20)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--figures", type=Path, default=None, help="copy the witness pictures here (e.g. docs/images)")
    p.add_argument("--pictures-only", action="store_true", help="only draw, from the testers already in --out")
    p.add_argument("--seeds", type=int, nargs="+", metavar="SEED", help="instead: train testers with these seeds and tabulate their exhaustive checks")
    p.add_argument("--trap-penalty", type=float, default=0.0, help="with --seeds: the testers' trap penalty")
    args = p.parse_args(argv)
    if args.seeds:
        table = seed_study(args.out, args.seeds, args.steps, args.trap_penalty)
        (args.out / "seeds.md").write_text(table)
        print(table)
        return 0
    if args.pictures_only:
        draw(args.out, args.figures, args.seed)
        return 0

    from agents.testers import problem_of
    from experiments.evaluation import evaluate, write_report
    from experiments.evaluation.results import TESTER_COLUMNS, tester_comparison_rows
    from experiments.training.system import train
    from experiments.training.tester import train_tester

    out: Path = args.out
    testers = out / "testers"
    testers.mkdir(parents=True, exist_ok=True)
    summaries = {}
    for problem in PROBLEMS:
        s = train_tester(problem, args.steps, testers / f"{problem}.zip", seed=args.seed, progress_bar=False, eval_episodes=args.episodes)
        s.pop("points")
        summaries[problem] = s
        f = s["fairness"]
        print(
            f"{problem:18s} trained {s['steps']} steps in {s['seconds']:6.1f} s; vs replanner realized before goal "
            f"{100 * s['realized_before_goal_rate']:.0f} %; exhaustive: {f['nodes']} states, "
            f"{'fair' if f['fair'] else str(f['traps']) + ' trap states'}, "
            f"{'guaranteed' if f['guaranteed'] else 'not guaranteed'}, illegal {f['illegal']}",
            flush=True,
        )
    (out / "testers.json").write_text(json.dumps(summaries, indent=1) + "\n")
    tester = f"ppo:{testers}"
    all_records = []
    for env_id in COMPARED:
        model = out / f"ppo-sut-{problem_of(env_id)[0]}.zip"
        s = train(env_id, args.sut_steps, model, seed=args.seed, progress_bar=False, eval_episodes=0)
        print(f"PPO system on {env_id}: {s['steps']} steps in {s['seconds']:.1f} s", flush=True)
        cells = evaluate([env_id], SUTS + [f"ppo:{model}"], args.episodes, args.seed, None, testers=["synthesized", tester])
        records = write_report(cells, out / f"evaluate-{env_id}")
        all_records += records
    (out / "comparison.json").write_text(json.dumps(all_records, indent=1, default=str) + "\n")
    lines = ["| " + " | ".join(TESTER_COLUMNS) + " |", "|" + "---|" * len(TESTER_COLUMNS)]
    for row in tester_comparison_rows(all_records):
        row[1] = "learned" if row[1] != "synthesized" else row[1]
        row[2] = "ppo" if row[2].startswith("ppo:") else row[2]
        lines.append("| " + " | ".join(row) + " |")
    table = "\n".join(lines) + "\n"
    (out / "comparison.md").write_text(table)
    print(table)
    draw(out, args.figures, args.seed)
    return 0


if __name__ == "__main__":
    sys.exit(main())
