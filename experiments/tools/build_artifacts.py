"""Synthesize the built-in problems and write the artifacts ``flowtest_env`` ships.

Usage::

    python -m experiments.tools.build_artifacts                 # every built-in missing its artifact
    python -m experiments.tools.build_artifacts maze2 --force   # rebuild one, overwriting it
    python -m experiments.tools.build_artifacts mars-exploration --node-limit 5000

Each artifact goes to ``flowtest_env/artifacts/<name>.json`` (or ``--out DIR``). An
existing file is never overwritten without ``--force``: the shipped artifacts are what
``gym.make`` loads, and ``tests/flowtest_env/test_envs.py`` proves each equals a fresh synthesis.
``SHA256SUMS`` in the same folder lists each file's SHA-256 (rewritten after every file):
``gym.make`` refuses a shipped artifact whose bytes differ, or whose own ``digest`` (written
with it) is not that of its content.

Shipped artifacts use deterministic budgets only (one HiGHS thread, a fixed seed, a node
limit per HiGHS run: :func:`flowtest_env.artifacts.artifact_options`), never a wall-clock
limit, so a rebuild on any machine, under any load, gives the same files (apart from
timings).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from flowtest_env.artifacts import (
    ARTIFACT_DIR,
    ARTIFACT_NODE_LIMIT,
    ARTIFACT_NODE_LIMITS,
    synthesize_artifact,
    write_manifest,
)
from synthesis.problems.builtins import BUILTINS


def build(names: list[str], out: Path, force: bool, node_limit: int | None = None) -> int:
    """Synthesize ``names`` into ``out``; returns the process exit code (2 if a file
    exists and ``force`` is off, 1 on an unknown name)."""
    unknown = [n for n in names if n not in BUILTINS]
    if unknown:
        print(f"unknown built-in problem(s): {', '.join(unknown)}; known: {', '.join(BUILTINS)}", file=sys.stderr)
        return 1
    existing = [n for n in names if (out / f"{n}.json").exists()]
    if existing and not force:
        print(
            f"refusing to overwrite {', '.join(str(out / f'{n}.json') for n in existing)}; pass --force",
            file=sys.stderr,
        )
        return 2
    out.mkdir(parents=True, exist_ok=True)
    for name in names:
        t = time.perf_counter()
        art = synthesize_artifact(name, node_limit)
        path = out / f"{name}.json"
        tmp = path.with_name(f".{path.name}.tmp")
        try:
            art.save(tmp)  # with the digest of its content (synthesis.artifacts.artifact.DIGEST_KEY)
            tmp.replace(path)
        finally:
            tmp.unlink(missing_ok=True)
        s = art.summary
        print(
            f"{name}: {s['status']}{' (stopped by ' + s['stopped_by'] + ')' if s.get('stopped_by') else ''}, "
            f"flow {s['flow']}, {s['n_cuts']} cuts, {time.perf_counter() - t:.1f} s -> {path}",
            flush=True,
        )
        write_manifest(out)  # after each file: an interrupted build leaves a true manifest
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", help="built-in problems (default: every one without an artifact)")
    ap.add_argument("--force", action="store_true", help="overwrite existing artifacts")
    ap.add_argument("--out", type=Path, default=ARTIFACT_DIR, help=f"output folder (default {ARTIFACT_DIR})")
    ap.add_argument(
        "--node-limit",
        type=int,
        default=None,
        metavar="N",
        help=f"branch-and-bound nodes per HiGHS run (default {ARTIFACT_NODE_LIMIT}, or the built-in's entry of "
        f"ARTIFACT_NODE_LIMITS: {ARTIFACT_NODE_LIMITS}; a deterministic budget: "
        "the answer may then be feasible, not proven optimal)",
    )
    args = ap.parse_args(argv)
    names = args.names or [n for n in BUILTINS if args.force or not (args.out / f"{n}.json").exists()]
    if not names:
        print("every built-in already has an artifact (use --force to rebuild)")
        return 0
    return build(names, args.out, args.force, args.node_limit)


if __name__ == "__main__":
    raise SystemExit(main())
