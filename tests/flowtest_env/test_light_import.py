"""Playing a shipped test loads no solver (issue 40, item 2; issue 44, start-up).

A fresh interpreter imports :mod:`flowtest_env`, makes ``FlowTest-Maze2-v0`` (a shipped
artifact: a test agent's test, checked in full on load), resets and steps it, loads a shipped
standard pool's train split (and a test agent's pool) and steps a vector env over them; after each stage no solver is in
``sys.modules``: no HiGHS or OR-Tools, no :mod:`synthesis.pipeline`, no test agent's
counterexample loop, no module of the routing step beyond its plain data
(:data:`ROUTING_DATA`). Synthesis is still there when a test needs it: the last stage
synthesizes a problem and the pipeline is then loaded (which shows the check can see it).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

SOLVER_PACKAGES = ("highspy", "ortools")
"""Solver libraries: neither may be imported to play a test."""

SOLVER_MODULES = ("synthesis.pipeline", "synthesis.test_agent.loop")
"""The synthesis entry point and the test agent's loop, which import every routing backend."""

ROUTING_DATA = (
    "synthesis.routing",
    "synthesis.routing.options",
    "synthesis.routing.solve_status",
    "synthesis.routing.groups",
    "synthesis.routing.result",
    "synthesis.routing.restrictions",
)
"""The only modules of :mod:`synthesis.routing` a played test may load, all plain data: the
options (which :class:`~synthesis.options.SynthesisOptions` extends and a pool's provenance
records) with the solve control they name, the cut groups (which the test agent's game reads),
the routing result and the restrictions rebuilt from it (a pool record's cuts)."""


STAGES = """
import json, sys

def solvers():
    return sorted(
        m for m in sys.modules
        if m.split(".")[0] in SOLVER_PACKAGES or m in SOLVER_MODULES
        or (m.startswith("synthesis.routing.") and m not in ROUTING_DATA)
    )

seen = {}
import gymnasium
import flowtest_env
seen["import flowtest_env"] = solvers()
env = gymnasium.make("FlowTest-Maze2-v0")
seen["make Maze2"] = solvers()
obs, info = env.reset(seed=0)
env.step(int(info["action_mask"].argmax()))
seen["reset and step"] = solvers()
from flowtest_env.standard_pools import load_standard_pool
tests = load_standard_pool("reachability1/5x5-v1", "train", count=8, workers=1)
seen["load a standard pool"] = solvers()
agent_tests = load_standard_pool("reachability1/5x5/blocked/agent-v1", "train", count=2, workers=1)
seen["load a test agent's standard pool"] = solvers()
from flowtest_env.vector import PoolVectorEnv
envs = PoolVectorEnv(4, tests + agent_tests)
obs, infos = envs.reset(seed=0)
envs.step(infos["action_mask"].argmax(axis=1))
seen["vector env step"] = solvers()
from synthesis import load_problem
flowtest_env.load_test(load_problem("small-reactive"))
seen["synthesize a problem"] = solvers()
print(json.dumps(seen))
"""


def test_playing_a_shipped_test_loads_no_solver() -> None:
    """Every stage of playing shipped tests leaves the solvers unloaded; synthesizing loads them."""
    head = f"SOLVER_PACKAGES = {SOLVER_PACKAGES!r}\nSOLVER_MODULES = {SOLVER_MODULES!r}\nROUTING_DATA = {ROUTING_DATA!r}\n"
    r = subprocess.run([sys.executable, "-c", head + STAGES], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    seen: dict[str, list[str]] = json.loads(r.stdout.strip().splitlines()[-1])
    synthesized = seen.pop("synthesize a problem")
    assert {stage: loaded for stage, loaded in seen.items() if loaded} == {}
    assert "synthesis.pipeline" in synthesized and "highspy" in synthesized  # the check sees a solver when one is loaded
