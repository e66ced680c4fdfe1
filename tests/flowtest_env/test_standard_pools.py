"""Standard pools: the registry, the shipped records (checked on load, a tampered record
refused, the full re-check on a sample), loading through ``load_pool``, the resumable
builder and the build progress."""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import flowtest_env.random_grid as rg
import flowtest_env.standard_pools as sp
from experiments.tools import build_pools
from flowtest_env.pools import load_pool
from synthesis.artifacts.pool_records import certificate_of, record_digest
from synthesis.model.errors import ProblemError
from synthesis.problems.problem import build_graphs
from synthesis.problems.random_worlds import world_problem
from synthesis.routing.restrictions import strategy_from_routing
from synthesis.routing.result import RoutingResult
from tests.testing_pools import copy_split, empty_data

SHIPPED = [p for p in sp.STANDARD_POOLS.values() if p.shipped("test")]
R1 = "reachability1/5x5-v1"


@pytest.fixture
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """An empty on-demand cache, and no pool kept in memory."""
    monkeypatch.setenv("FLOWTEST_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(rg, "_POOLS", {})
    return tmp_path / "cache"


@pytest.fixture
def data(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """An empty folder in place of the shipped records."""
    return empty_data(tmp_path, monkeypatch)


# ------------------------------------------------------------------- the registry


def test_registry_names_versions_and_planned_splits() -> None:
    assert R1 in sp.STANDARD_POOLS
    for pid, pool in sp.STANDARD_POOLS.items():
        assert pid == pool.id == f"{pool.pool}-v{pool.version}"
        assert sp.is_standard(pid) and not sp.is_standard(pool.pool)
        pool.name  # parses  # noqa: B018
        assert pool.splits["train"] >= 4096 and pool.splits["validation"] >= 1
        assert pool.splits["test"] >= (250 if pool.slow else 1000)


def test_unknown_ids_are_refused_with_the_choices() -> None:
    with pytest.raises(ValueError, match="ships reachability1/5x5-v1"):
        sp.standard_pool("reachability1/5x5-v9")
    with pytest.raises(ValueError, match="expected one of"):
        sp.standard_pool("reachability1/6x6-v1")
    with pytest.raises(ValueError, match="unknown split"):
        sp.load_standard_pool(R1, "holdout")
    with pytest.raises(ValueError, match="unknown check"):
        sp.load_standard_pool(R1, "test", 1, check="none")


def test_shipped_pools_have_the_current_parameters() -> None:
    """A pool's tests depend on its parameters (budget included): a changed value needs a
    new version of the pool, so the recorded parameters must be today's."""
    for pool in sp.STANDARD_POOLS.values():
        meta = pool.folder / "pool.json"
        if meta.exists():
            recorded = json.loads(meta.read_text(encoding="utf-8"))
            assert recorded["id"] == pool.id and recorded["pool"] == pool.pool
            assert sp.changed_params(recorded["params"], pool.params()) == [], pool.id


def test_changed_params_names_changed_values_only() -> None:
    assert sp.changed_params({"a": 1, "o": {"x": 1, "y": 2}}, {"a": 1, "o": {"x": 1, "y": 3, "new": 0}}) == ["o.y"]
    assert sp.changed_params({"a": 1, "old": 2}, {"a": 1}) == []


# ---------------------------------------------------------------- shipped records


def test_the_continuity_pool_ships_its_held_out_split() -> None:
    assert sp.standard_pool(R1).shipped("test") >= 1000


@pytest.mark.parametrize("pool", SHIPPED, ids=lambda p: p.id)
def test_shipped_files_are_compact_certified_and_in_seed_order(pool: sp.StandardPool) -> None:
    for split in rg.SPLITS:
        records = sp.read_records(pool, split)  # raises unless the split's seeds in order
        if not records:
            continue
        keyed = {"content"} if pool.draw == "content" else set()  # a -v2 record carries its test's content key
        assert all(set(r) == {"seed", "attempt", "cuts", "static", "summary", "digest", "certificate", *keyed} for r in records)
        assert all(r["digest"] == {"sha256": record_digest(r)} for r in records)
        per_test = pool.path(split).stat().st_size / len(records)
        assert per_test < 500, f"{pool.id} {split}: {per_test:.0f} bytes a test"


@pytest.mark.parametrize("pool", SHIPPED, ids=lambda p: p.id)
def test_a_sample_passes_the_full_recheck_and_equals_the_certified_load(pool: sp.StandardPool) -> None:
    """The full re-check (every check of a fresh synthesis) on a sample of each shipped
    pool, spread over the split; the fast load gives the same tests."""
    n = pool.shipped("test")
    for start in sorted({0, n // 2, n - 1}):
        (full,) = sp.load_standard_pool(pool.id, "test", 1, start, check="full")
        (fast,) = sp.load_standard_pool(pool.id, "test", 1, start)
        assert full.to_dict() == fast.to_dict()
        assert full.summary["bypass_flow"] == 0 and full.summary["flow"] >= 1


def test_a_fresh_synthesis_gives_the_shipped_record(cache: Path) -> None:
    """Shipped records are what the pool's budget synthesizes for those seeds today."""
    pool = sp.standard_pool(R1)
    shipped = sp.read_records(pool, "test")[:2]
    p = pool.name
    for rec in shipped:
        fresh = rg.pool_record(p.size, p.family, p.n, rec["seed"], p.kind, p.world)
        strip = ("digest", "certificate")
        assert {k: v for k, v in fresh.items() if k not in strip} == {k: v for k, v in rec.items() if k not in strip}


# ---------------------------------------------------------------- tampering


def _add_cut(records: list[dict[str, Any]]) -> None:
    cuts = records[1]["cuts"]
    records[1]["cuts"] = sorted({*cuts, next(e for e in range(10_000) if e not in cuts)})


def _edit_summary(records: list[dict[str, Any]]) -> None:
    records[1]["summary"]["status"] = "feasible"


@pytest.mark.parametrize("edit", [_add_cut, _edit_summary], ids=["one-more-cut", "summary-edited"])
def test_a_tampered_record_is_refused_naming_file_line_and_seed(data: Path, edit: Any) -> None:
    pool = sp.standard_pool(R1)
    copy_split(pool, "test", data, 3, edit=edit)
    assert sp.load_standard_pool(R1, "test", 1)  # the record before it is fine
    with pytest.raises(ProblemError, match=r"test\.jsonl\.gz, line 2: pool record of seed 2000001: the record was changed"):
        sp.load_standard_pool(R1, "test", 3)
    with pytest.raises(ProblemError, match="line 2"):
        sp.load_standard_pool(R1, "test", 3, check="full")


def test_a_record_with_a_resealed_digest_fails_its_certificate(data: Path) -> None:
    """One more cut, the digest written anew: the certificate no longer matches."""

    def reseal(records: list[dict[str, Any]]) -> None:
        _add_cut(records)
        records[1]["digest"] = {"sha256": record_digest(records[1])}

    copy_split(sp.standard_pool(R1), "test", data, 2, edit=reseal)
    with pytest.raises(ProblemError, match="line 2: .*certificate says were checked"):
        sp.load_standard_pool(R1, "test", 2)


def _without_cuts_resealed(pool: sp.StandardPool, rec: dict[str, Any]) -> None:
    """Drop every cut of a record and forge its certificate and digest to match, as a
    forger who knows both definitions would."""
    p = pool.name
    problem = world_problem(p.size, p.family, p.n, rec["seed"], rec["attempt"], p.world, p.kind)
    _, products = build_graphs(problem)
    routing = RoutingResult(
        status="optimal",
        flow=rec["summary"]["flow"],
        cut_edges=np.zeros(0, dtype=np.int64),
        cut_group_keys=[],
        static_moves_cut=np.zeros(products.ts.n_moves, dtype=bool),
        blocked_places=np.zeros(0, dtype=np.int64),
        mip_gap=0.0,
        stats={},
    )
    rec["cuts"] = []
    rec["certificate"] = certificate_of(products, strategy_from_routing(products, routing, "instantaneous"), rec["summary"]["flow"])
    rec["digest"] = {"sha256": record_digest(rec)}


def test_a_forged_certificate_still_meets_the_bypass_search(data: Path) -> None:
    """A record without its cuts, certificate and digest forged to match: the fast load's
    bypass search still finds the execution that avoids the test objective (the
    full check too)."""
    pool = sp.standard_pool(R1)
    copy_split(pool, "test", data, 1, edit=lambda rs: _without_cuts_resealed(pool, rs[0]))
    with pytest.raises(ProblemError, match="bypass flow is not 0"):
        sp.load_standard_pool(R1, "test", 1)
    with pytest.raises(ProblemError, match="fails its check"):
        sp.load_standard_pool(R1, "test", 1, check="full")


@pytest.mark.parametrize("small_graph", [True, False], ids=["depth-first", "sparse-matrix"])
def test_both_bypass_searches_find_the_bypass_of_a_forged_record(data: Path, monkeypatch: pytest.MonkeyPatch, small_graph: bool) -> None:
    """The search over adjacency lists (a pool test's small G) and the one over a sparse
    matrix (a large G) pass the shipped records and find the bypass of a forged one."""
    import synthesis.artifacts.pool_records as records

    if not small_graph:
        monkeypatch.setattr(records, "SMALL_GRAPH", -1)
    pool = sp.standard_pool(R1)
    copy_split(pool, "test", data, 2, edit=lambda rs: _without_cuts_resealed(pool, rs[1]))
    assert len(sp.load_standard_pool(R1, "test", 1, workers=1)) == 1  # the record before it passes
    with pytest.raises(ProblemError, match="line 2: .*bypass flow is not 0"):
        sp.load_standard_pool(R1, "test", 2, workers=1)


def test_a_damaged_file_is_refused(data: Path) -> None:
    pool = sp.standard_pool(R1)
    path = data / pool.slug / "test.jsonl.gz"
    path.parent.mkdir(parents=True)
    path.write_bytes(b"not gzip")
    with pytest.raises(ProblemError, match="not a gzipped records file"):
        sp.load_standard_pool(R1, "test", 1)
    copy_split(pool, "test", data, 3, edit=lambda rs: rs.pop(1))
    with pytest.raises(ProblemError, match="line 2: expected the record of seed 2000001"):
        sp.load_standard_pool(R1, "test", 2)


# ---------------------------------------------------------------- load_pool


def test_load_pool_serves_shipped_tests_then_builds_the_rest(data: Path, cache: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pool = sp.standard_pool(R1)
    copy_split(pool, "test", data, 2)
    seen: list[int] = []
    real = rg.pool_record

    def counted(*args: Any) -> dict[str, Any]:
        seen.append(args[3])
        return real(*args)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(rg, "pool_record", counted)
        tests = load_pool(R1, "test", 3)
    assert seen == [2_000_002]  # only the seed not shipped
    assert [t.summary["n_cuts"] for t in tests[:2]] == [r["summary"]["n_cuts"] for r in sp.read_records(pool, "test")]
    assert "1/1 tests" in capsys.readouterr().err  # the build of the one seed not shipped
    with pytest.raises(ValueError, match="ships 2 tests"):
        sp.load_standard_pool(R1, "test", 3)


# ---------------------------------------------------------------- the builder


def test_builder_resumes_is_deterministic_and_survives_ctrl_c(data: Path, cache: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    pool = sp.standard_pool(R1)
    assert build_pools.build_split(pool, "validation", 2, reuse_cache=False) == 2
    path = pool.path("validation")
    first = path.read_bytes()
    assert build_pools.build_split(pool, "validation", 3, reuse_cache=False) == 3  # resumes: keeps the first two
    records = sp.read_records(pool, "validation")
    assert [r["seed"] for r in records] == [1_000_000, 1_000_001, 1_000_002]
    sp.write_records(tmp_path / "two.gz", records[:2])
    assert (tmp_path / "two.gz").read_bytes() == first  # same records, same bytes
    assert (data / pool.slug / "pool.json").exists()

    real = rg.synthesize_records

    def interrupted(*args: Any) -> Any:
        for k, item in enumerate(real(*args)):
            if k == 1:
                raise KeyboardInterrupt
            yield item

    monkeypatch.setattr(build_pools, "synthesize_records", interrupted)
    with pytest.raises(KeyboardInterrupt):
        build_pools.build_split(pool, "validation", 6, reuse_cache=False)
    assert [r["seed"] for r in sp.read_records(pool, "validation")] == [1_000_000, 1_000_001, 1_000_002, 1_000_003]
    assert sp.load_standard_pool(R1, "validation")  # what was written loads
    assert not list(path.parent.glob(".*tmp"))


def test_builder_refuses_a_pool_built_with_other_parameters(data: Path) -> None:
    pool = sp.standard_pool(R1)
    meta = data / pool.slug / "pool.json"
    meta.parent.mkdir(parents=True)
    params = pool.params()
    params["options"]["node_limit"] += 1
    meta.write_text(json.dumps({"id": pool.id, "pool": pool.pool, "params": params}), encoding="utf-8")
    with pytest.raises(ProblemError, match="needs a new version"):
        build_pools.check_meta(pool)


def test_builder_command_line_errors(capsys: pytest.CaptureFixture[str]) -> None:
    assert build_pools.main(["reachability1/5x5-v7"]) == 2
    assert capsys.readouterr().err.startswith("error: ")
    assert build_pools.main(["--list"]) == 0
    assert R1 in capsys.readouterr().out


# ---------------------------------------------------------------- progress


def test_progress_lines_off_a_terminal_say_done_rate_and_time_left() -> None:
    out = io.StringIO()
    bar = rg.BuildProgress(total=4, initial=0, desc="pool x", stream=out, every=0.0)
    for _ in range(3):
        bar.update(1)
    bar.update(1)
    bar.close()
    lines = out.getvalue().splitlines()
    assert lines[0] == "pool x: 0/4 tests"
    assert "pool x: 3/4 tests" in lines[3] and "s/test" in lines[3] and "left" in lines[3]
    assert "4/4 tests" in lines[-1] and "in all" in lines[-1]


def test_progress_off_a_terminal_is_throttled() -> None:
    out = io.StringIO()
    bar = rg.BuildProgress(total=100, initial=0, desc="p", stream=out, every=3600.0)
    for _ in range(99):
        bar.update(1)
    assert len(out.getvalue().splitlines()) == 1  # the opening line only
    bar.update(1)
    assert "100/100" in out.getvalue().splitlines()[-1]  # the end is always shown


def test_a_load_shows_its_progress_when_asked_or_large(capsys: pytest.CaptureFixture[str]) -> None:
    sp.load_standard_pool(R1, "test", 2, progress=True)
    assert "loading reachability1/5x5-v1 test: 2/2 tests" in capsys.readouterr().err
    sp.load_standard_pool(R1, "test", 2)  # small: quiet unless asked
    assert capsys.readouterr().err == ""


def test_the_builder_reuses_cached_records_of_the_same_parameters_only(cache: Path) -> None:
    """Records cached under another version are reused (and checked) only where that
    version's pool parameters have today's values: another budget may give other tests."""
    here = rg.pool_dir(5, "reachability", 1, "reactive")
    record = {"seed": 1_000_000, "attempt": 0}
    for name, change in (("same", {}), ("other-budget", {"node_limit": 7})):
        folder = here.parent / name
        folder.mkdir(parents=True)
        params = rg.pool_params(5, "reachability", 1, "reactive")
        params["options"].update(change)
        (folder / "key.json").write_text(json.dumps({"params": params}), encoding="utf-8")
        (folder / "validation.jsonl").write_text(json.dumps({**record, "from": name}) + "\n", encoding="utf-8")
    found = rg.stored_records(5, "reachability", 1, "validation", any_version=True)
    assert [r["from"] for r in found.values()] == ["same"]
    assert rg.stored_records(5, "reachability", 1, "validation") == {}  # the current version's folder only


def test_builder_appends_in_seed_order_whatever_order_records_finish(data: Path, cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Through Ray records finish in any order; the file still holds the split's seeds in order."""
    real = rg.synthesize_records

    def shuffled(*args: Any) -> Any:
        return reversed(list(real(*args)))

    monkeypatch.setattr(build_pools, "synthesize_records", shuffled)
    pool = sp.standard_pool(R1)
    assert build_pools.build_split(pool, "validation", 3, reuse_cache=False) == 3
    assert [r["seed"] for r in sp.read_records(pool, "validation")] == [1_000_000, 1_000_001, 1_000_002]


def test_a_random_grid_env_takes_a_standard_id_as_the_same_seeds() -> None:
    from flowtest_env.pools import random_grid_arguments

    std = random_grid_arguments(R1, "test", 4, 5, "reachability", None, (), "reactive")
    assert std == random_grid_arguments("reachability1/5x5", "test", 4, 5, "reachability", None, (), "reactive")
    with pytest.raises(ValueError, match="not a standard pool"):
        random_grid_arguments("reachability1/5x5-v9", "test", 4, 5, "reachability", None, (), "reactive")


# ---------------------------------------------------------------- loading in two processes


def test_two_processes_load_the_same_tests_in_the_same_order(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr(sp, "CHUNK", 16)
    one = sp.load_standard_pool(R1, "test", 72, 5, workers=1)
    two = sp.load_standard_pool(R1, "test", 72, 5, workers=2, progress=True)
    assert [a.to_dict() for a in two] == [a.to_dict() for a in one]
    assert "loading reachability1/5x5-v1 test: 72/72 tests" in capsys.readouterr().err
    assert sp.auto_workers(sp.PARALLEL_FROM - 1) == 1  # a small load stays in this process
    with pytest.raises(ValueError, match="workers must be a positive integer"):
        sp.load_standard_pool(R1, "test", 2, workers=0)


def test_a_load_without_shared_memory_runs_in_this_process(monkeypatch: pytest.MonkeyPatch) -> None:
    import multiprocessing.context

    def no_counter(*args: Any, **kwargs: Any) -> Any:
        raise OSError("no /dev/shm here")

    monkeypatch.setattr(multiprocessing.context.BaseContext, "Value", no_counter)
    monkeypatch.setattr(sp, "CHUNK", 4)
    assert [a.name for a in sp.load_standard_pool(R1, "test", 9, workers=2)] == [a.name for a in sp.load_standard_pool(R1, "test", 9, workers=1)]


def test_two_processes_refuse_the_record_one_process_refuses_first(data: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Two tampered records in chunks of several processes: the refusal names the first
    line, as a load in one process does, whichever process met its record first."""
    monkeypatch.setattr(sp, "CHUNK", 4)

    def two_edits(records: list[dict[str, Any]]) -> None:
        records[22]["summary"]["status"] = "feasible"
        records[9]["summary"]["status"] = "feasible"

    copy_split(sp.standard_pool(R1), "test", data, 24, edit=two_edits)
    with pytest.raises(ProblemError) as one:
        sp.load_standard_pool(R1, "test", 24, workers=1)
    assert "line 10: pool record of seed 2000009: the record was changed" in str(one.value)
    for workers in (2, 3):
        with pytest.raises(ProblemError) as many:
            sp.load_standard_pool(R1, "test", 24, workers=workers)
        assert str(many.value) == str(one.value)


def test_ctrl_c_stops_a_load_in_two_processes_within_a_second(tmp_path: Path) -> None:
    """Ctrl-C on a terminal reaches the whole process group: the load stops, its helper
    with it, and nothing of the group is left."""
    import os
    import signal
    import subprocess
    import sys
    import time

    script = (
        "import multiprocessing, signal, sys\n"
        "signal.signal(signal.SIGINT, signal.default_int_handler)\n"  # as on a terminal: a job started in the background inherits SIGINT ignored
        "from flowtest_env.standard_pools import load_standard_pool\n"
        "try:\n"
        "    load_standard_pool('reachability1/5x5-v2', 'train', 4096, progress=True, workers=2)\n"
        "except KeyboardInterrupt:\n"
        "    print('interrupted', len(multiprocessing.active_children()), file=sys.stderr, flush=True)\n"
        "    sys.exit(130)\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", script], stderr=subprocess.PIPE, text=True, start_new_session=True)
    assert proc.stderr is not None
    line = proc.stderr.readline()
    assert "loading reachability1/5x5-v2 train" in line, line
    time.sleep(1.0)  # the helper is at work
    sent = time.monotonic()
    os.killpg(proc.pid, signal.SIGINT)
    err = proc.stderr.read()
    assert proc.wait(timeout=10) == 130, err
    took = time.monotonic() - sent
    assert took < 1.0, f"stopped {took:.2f} s after Ctrl-C"
    assert "interrupted 0" in err and "Traceback" not in err, err
    time.sleep(0.2)
    with pytest.raises(ProcessLookupError):
        os.killpg(proc.pid, 0)  # no process of the group is left


def test_random_grid_envs_take_a_standard_pools_shipped_records(monkeypatch: pytest.MonkeyPatch) -> None:
    """``gymnasium.make("FlowTest-RandomGrid-v0", pool=<standard id>)`` and its vector env
    load the shipped records (what SB3 training on a standard pool uses): nothing is built,
    and the tests are those ``load_pool`` gives."""
    import gymnasium as gym

    import flowtest_env.random_grid as random_grid
    from flowtest_env.vector import RandomGridVectorEnv

    want = [t.to_dict() for t in load_pool(R1, "train", 5)]

    def no_build(*args: object, **kwargs: object) -> None:
        raise AssertionError("a standard pool's shipped tests were built again")

    monkeypatch.setattr(random_grid, "build_pool", no_build)
    monkeypatch.setattr(random_grid, "_POOLS", {})  # nothing built earlier in this process either
    env = gym.make("FlowTest-RandomGrid-v0", pool=R1, split="train", count=5)
    assert [g.artifact.to_dict() for g in env.unwrapped.games] == want
    venv = RandomGridVectorEnv(2, pool=R1, split="train", count=5)
    assert [g.artifact.to_dict() for g in venv.games] == want
