"""Check FlowTest against the newest dependency versions that ``pyproject.toml`` allows.

The README's commands install from the lock (``requirements/lock.txt``), so a user who follows
them gets the versions CI tested. People who install FlowTest into an environment of their own
get whatever the ranges in ``pyproject.toml`` admit; this script tells whether those newest
versions still give the right answers. It makes a throw-away virtual environment, installs
FlowTest with the ``test`` extra and no constraints (pip's eager upgrade: the newest release of
every dependency within the ranges), and runs the tests that hold our answers to the truth: the
exhaustive-optimality tests, the command line and the environment checks.

Not part of the default CI run (it resolves against whatever the registry holds today).

Usage::

    python -m experiments.tools.newest_versions [--keep DIR] [--tests PATH ...]

Prints a Markdown report (the versions installed, the test outcome) for docs/install.md;
exit 0 when the tests pass, 1 when they fail, 2 when the environment cannot be built.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_TESTS = ("tests/synthesis/test_optimality.py", "tests/experiments/test_cli.py", "tests/flowtest_env/test_envs.py")
REPORTED = ("highspy", "numpy", "scipy", "networkx", "gymnasium", "pettingzoo", "matplotlib", "hypothesis", "pytest")


def _run(cmd: list[str], **kwargs: object) -> subprocess.CompletedProcess[str]:
    return subprocess.run(cmd, text=True, capture_output=True, **kwargs)  # type: ignore[call-overload, no-any-return]


def build(venv: Path) -> dict[str, str]:
    """A fresh venv at ``venv`` with FlowTest[test] at the newest allowed versions; their versions."""
    made = _run([sys.executable, "-m", "venv", str(venv)])
    if made.returncode != 0:
        raise RuntimeError(f"python -m venv failed:\n{made.stderr}")
    pip = [str(venv / "bin" / "python"), "-m", "pip"]
    env = {k: v for k, v in os.environ.items() if k not in ("PIP_CONSTRAINT", "PIP_REQUIRE_VIRTUALENV")}
    installed = _run(
        [*pip, "install", "--no-cache-dir", "--upgrade", "--upgrade-strategy", "eager", "-e", f"{ROOT}[test]"],
        env=env,
    )
    if installed.returncode != 0:
        raise RuntimeError(f"pip install failed:\n{installed.stdout[-4000:]}\n{installed.stderr[-4000:]}")
    listed = _run([*pip, "list", "--format", "json"])
    return {p["name"].lower(): p["version"] for p in json.loads(listed.stdout)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--keep", type=Path, default=None, help="build the environment here and keep it")
    ap.add_argument("--tests", nargs="+", default=list(DEFAULT_TESTS), help="test paths to run")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="flowtest-newest-") as tmp:
        venv = args.keep if args.keep is not None else Path(tmp) / "venv"
        cache = Path(tmp) / "cache"
        t0 = time.perf_counter()
        try:
            versions = build(venv)
        except RuntimeError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        env = {**os.environ, "XDG_CACHE_HOME": str(cache)}
        tested = subprocess.run(
            [str(venv / "bin" / "python"), "-m", "pytest", "-q", "-n", "2", "-p", "no:cacheprovider", *args.tests],
            cwd=ROOT,
            text=True,
            capture_output=True,
            env=env,
        )
        elapsed = time.perf_counter() - t0
    closing = [line for line in tested.stdout.splitlines() if line.strip()][-1:] or ["(no output)"]
    failed = [line for line in tested.stdout.splitlines() if line.startswith("FAILED")]
    print(f"### Newest allowed versions, {time.strftime('%Y-%m-%d')}\n")
    print("| package | version |\n|---|---|")
    for name in REPORTED:
        print(f"| {name} | {versions.get(name, '(not installed)')} |")
    print(f"\nTests: `{' '.join(args.tests)}` -> {closing[0].strip()} ({elapsed:.0f} s with the install)")
    for line in failed:
        print(f"- {line}")
    return 0 if tested.returncode == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
