"""A seed names the same test everywhere (issue 12, point 6).

Random grid pools are synthesized with deterministic budgets only, filed under a key
that carries the FlowTest and solver versions and the options, rebuilt (not reused)
under another version, the same when built twice (also with every core busy, and through
Ray: slow tests), and the test suite itself never writes into the user's real home.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

import flowtest_env.random_grid as rg
from synthesis.artifacts import provenance
from synthesis.artifacts.summary import stop_note, without_timings
from synthesis.pipeline import SynthesisOptions, synthesize
from synthesis.problems.random_grid import first_consistent, random_problem
from tests.testing_processes import BURNER

ROOT = Path(__file__).resolve().parents[2]
POOL = (5, "reachability", 1)  # a few seconds per pool of three seeds
SEEDS = (0, 1, 2)


def pool_files(cache: Path) -> dict[str, bytes]:
    """Every file of a cache folder, relative name -> its bytes (pool files hold no timings)."""
    return {str(p.relative_to(cache)): p.read_bytes() for p in sorted(cache.rglob("*")) if p.is_file()}


@pytest.fixture
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """An empty cache folder, and no pool kept in memory."""
    monkeypatch.setenv("FLOWTEST_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(rg, "_POOLS", {})
    return tmp_path / "cache"


def count_syntheses(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Record the seeds :mod:`flowtest_env.random_grid` synthesizes from now on."""
    seen: list[int] = []
    real = rg.pool_record

    def counted(size: int, family: str, n: int, seed: int, kind: str = "reactive", world: str = "empty") -> dict[str, Any]:
        seen.append(seed)
        return real(size, family, n, seed, kind, world)

    monkeypatch.setattr(rg, "pool_record", counted)
    return seen


def build_in(cache: Path, monkeypatch: pytest.MonkeyPatch, **kw: Any) -> dict[str, bytes]:
    monkeypatch.setenv("FLOWTEST_CACHE_DIR", str(cache))
    rg.build_pool(*POOL, SEEDS, "reactive", progress=False, **kw)
    return pool_files(cache)


def test_the_suite_runs_in_a_sandbox() -> None:
    """conftest.py points the cache, HOME and XDG folders into a temporary folder."""
    from flowtest_env.artifacts import cache_dir

    sandbox = Path(os.environ["FLOWTEST_TEST_SANDBOX"])
    real_home = Path(os.environ["FLOWTEST_TEST_REAL_HOME"])
    assert sandbox != real_home and real_home not in sandbox.parents
    for path in (Path.home(), cache_dir(), Path(os.environ["XDG_CACHE_HOME"])):
        assert sandbox in path.parents, path


def test_pool_is_deterministic_and_keyed(cache: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Two builds of one pool give byte-identical files: one compact record per seed
    (no timings) in its split's file, and the pool's budget (deterministic, no wall
    clock) and the versions it was made under in ``key.json``."""
    first = build_in(tmp_path / "a", monkeypatch)
    second = build_in(tmp_path / "b", monkeypatch)
    assert first == second
    names = sorted(first)
    key = rg.pool_key(*POOL, "reactive")
    assert names == sorted(f"random-grid/5x5-reachability1-reactive/{key}/{f}" for f in ["key.json", "train.jsonl"])
    info = json.loads(first[names[0]])
    assert info["versions"] == provenance.versions()
    assert info["params"]["options"]["node_limit"] == rg.POOL_NODE_LIMIT
    assert info["params"]["options"]["work_limit"] == rg.POOL_WORK_LIMIT
    assert info["params"]["options"]["time_limit"] is None
    records = [json.loads(line) for line in first[names[1]].decode().splitlines()]
    assert [r["seed"] for r in records] == list(SEEDS)
    for r in records:
        assert r["summary"]["deterministic"] is True
        assert without_timings(r) == r
    for art in rg.build_pool(*POOL, SEEDS, progress=False):
        assert art.extras["provenance"]["versions"] == provenance.versions()
        assert art.extras["provenance"]["pool"]["options"]["node_limit"] == rg.POOL_NODE_LIMIT


def test_pool_is_reused_under_the_same_versions_and_rebuilt_under_others(cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    seen = count_syntheses(monkeypatch)
    pool = rg.build_pool(*POOL, SEEDS, progress=False)
    assert seen == list(SEEDS)
    again = rg.build_pool(*POOL, SEEDS, progress=False)
    assert seen == list(SEEDS), "the same versions must reuse the cache"
    assert [a.to_dict() for a in again] == [a.to_dict() for a in pool]
    real, real_key = provenance.versions(), rg.pool_key(*POOL, "reactive")
    for name in ("flowtest", "flowtest_source", "highspy"):
        other = dict(real, **{name: real[name] + "-other"})
        monkeypatch.setattr(provenance, "versions", lambda other=other: other)
        seen.clear()
        assert rg.pool_key(*POOL, "reactive") != real_key
        rg.build_pool(*POOL, SEEDS, progress=False)
        assert seen == list(SEEDS), f"a pool built under another {name} version was reused"
    assert len(list((cache / "random-grid" / "5x5-reachability1-reactive").iterdir())) == 4


def test_pool_key_carries_versions_and_options(monkeypatch: pytest.MonkeyPatch) -> None:
    key = rg.pool_key(*POOL, "reactive")
    assert rg.pool_key(*POOL, "static") != key
    assert rg.pool_key(5, "reachability", 2, "reactive") != key
    monkeypatch.setattr(rg, "POOL_NODE_LIMIT", rg.POOL_NODE_LIMIT + 1)
    assert rg.pool_key(*POOL, "reactive") != key
    monkeypatch.undo()
    real = provenance.versions()
    monkeypatch.setattr(provenance, "versions", lambda: dict(real, highspy="0.0.1"))
    assert rg.pool_key(*POOL, "reactive") != key


def test_damaged_cache_entry_is_rebuilt(cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    rg.build_pool(*POOL, (0,), progress=False)
    path = rg.pool_path(*POOL, 0, "reactive")
    good = path.read_text()
    path.write_text(good[: len(good) // 2])
    seen = count_syntheses(monkeypatch)
    with pytest.warns(UserWarning, match="refused a cache entry"):
        (art,) = rg.build_pool(*POOL, (0,), progress=False)
    assert seen == [0] and art.name.startswith("random-5x5")
    assert path.read_text() == good


def test_bad_pool_arguments_raise() -> None:
    with pytest.raises(ValueError, match="family"):
        rg.build_pool(5, "liveness", 1, (0,))
    with pytest.raises(ValueError, match="parallel"):
        rg.build_pool(*POOL, (0,), parallel="threads")
    with pytest.raises(ValueError, match="kind"):
        rg.build_pool(*POOL, (0,), kind="mixed")
    with pytest.raises(ValueError, match="world"):
        rg.build_pool(*POOL, (0,), world="lava")


def test_node_limit_is_a_reported_deterministic_budget() -> None:
    """A solve stopped by the node limit says so and is deterministic; a wall-clock
    limit makes the answer depend on the machine, and the summary says that too. The node
    limit bounds HiGHS (this model's 426 rows go to CP-SAT under ``auto``, bounded by
    ``work_limit`` instead: pools set both, :func:`rg.pool_options`)."""
    from synthesis.artifacts.summary import summary_of

    attempt, _, _ = first_consistent(5, "reachability", 1, 0)
    problem = random_problem(5, "reachability", 1, 0, attempt, "reactive")
    runs = [synthesize(problem, SynthesisOptions(node_limit=1, backend="highs")) for _ in range(2)]
    for test in runs:
        s = summary_of(test)
        assert (s["status"], s["stopped_by"], s["deterministic"]) == ("feasible", "node_limit", True)
        assert "node limit" in stop_note(s) and test.checks.ok
    assert [t.routing.cut_edges.tolist() for t in runs[:1]] == [t.routing.cut_edges.tolist() for t in runs[1:]]
    full = summary_of(synthesize(problem))
    assert (full["status"], full["stopped_by"], full["deterministic"]) == ("optimal", None, True)
    timed = summary_of(synthesize(problem, SynthesisOptions(time_limit=60)))
    assert timed["deterministic"] is False and "wall-clock" in stop_note(timed)


def test_progress_bar_goes_to_stderr(cache: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rg.build_pool(*POOL, (0,), progress=True)
    out, err = capsys.readouterr()
    assert out == "" and "1/1" in err


def test_the_suite_never_touches_the_real_home(tmp_path: Path) -> None:
    """Run a pool-building test in a fresh pytest whose HOME is an empty folder, with no
    cache variables set: the folder stays empty, the cache went to the sandbox."""
    home = tmp_path / "fake-home"
    home.mkdir()
    env = {k: v for k, v in os.environ.items() if not k.startswith(("XDG_", "FLOWTEST_", "MPLCONFIGDIR"))}
    env["HOME"] = str(home)
    test = "tests/flowtest_env/test_pools.py::test_progress_bar_goes_to_stderr"
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", test],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "1 passed" in done.stdout
    assert list(home.rglob("*")) == []


# ---------------------------------------------------------------- slow: load and Ray


@pytest.mark.slow
def test_pool_is_the_same_with_every_core_busy(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The acceptance test of issue 12: building the same pool again while a CPU burner
    runs on every core gives the same files apart from timings."""
    quiet = build_in(tmp_path / "quiet", monkeypatch)
    burners = [subprocess.Popen([sys.executable, "-c", BURNER]) for _ in range(os.cpu_count() or 2)]
    try:
        busy = build_in(tmp_path / "busy", monkeypatch)
    finally:
        for p in burners:
            p.kill()
            p.wait()
    assert busy == quiet


@pytest.mark.slow
def test_pool_through_ray_equals_in_process(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    pytest.importorskip("ray")
    local = build_in(tmp_path / "local", monkeypatch)
    remote = build_in(tmp_path / "ray", monkeypatch, parallel="ray", workers=2)
    assert remote == local
