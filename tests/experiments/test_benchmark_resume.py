"""An interrupted benchmark leaves its finished runs resumable (issue 43, item 3; issue 41,
item 5): ``flowtest benchmark --resume`` keeps them, trains the rest and gives the table of an
uninterrupted run; other settings are refused with one line; a partial file never looks
finished. And every ``--sut`` model is checked before any work (item 6)."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from experiments import benchmark as bench
from experiments.benchmark import resume
from experiments.cli.cli import main
from synthesis.model.errors import ProblemError
from tests.testing_processes import start_until

pytest.importorskip("torch")

FLOWTEST = Path(sys.executable).parent / "flowtest"
POOL = "safety2/4x4"
SMALL = [
    "--pool",
    POOL,
    "--train-count",
    "4",
    "--test-count",
    "3",
    "--validation-count",
    "2",
    "--sut",
    "ppo",
    "scripted:replanner",
    "--steps",
    "1024",
    "--seeds",
    "0",
    "1",
    "--curve-points",
    "2",
    "--curve-sizes",
    "2",
    "--curve-seeds",
    "1",
    "--workers",
    "1",
    "--bootstrap",
    "200",
]
"""Three training runs of a second each (two seeds and one point of the generalization curve)."""


def run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    try:
        code = main(argv)
    except SystemExit as exc:
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    return code, out, err


def _results(doc: dict[str, Any]) -> dict[str, Any]:
    """What a benchmark measured, without the times and the paths."""
    for e in doc["systems"]:
        for r in e["runs"]:
            r.pop("sut")
        for t in e.get("training", []):
            t.pop("seconds"), t.pop("curve_seconds"), t.pop("model")
    return {k: doc[k] for k in ("systems", "generalization", "scale", "headline", "budget", "config")}


def test_a_sigtermed_benchmark_resumes_to_the_table_of_an_uninterrupted_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, stdout, err = run(["benchmark", *SMALL, "--out", str(tmp_path / "whole"), "--json", "-q"], capsys)
    assert code == 0, err
    whole = json.loads(stdout)
    out = tmp_path / "stopped"
    proc = start_until([str(FLOWTEST), "benchmark", *SMALL, "--out", str(out)], "maskable-ppo seed 0 on 4 tests", signal.SIGTERM)
    proc.send_signal(signal.SIGTERM)  # in the middle: the first run finished, the second training
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert sorted(p.name for p in (out / "models").iterdir()) == ["maskable-ppo-seed0.json", "maskable-ppo-seed0.zip"]
    for f in (out / "pool").rglob("*.json"):
        json.loads(f.read_text())  # every test file written whole
    kept = (out / "models" / "maskable-ppo-seed0.zip").read_bytes()
    code, stdout, err = run(["benchmark", *SMALL, "--out", str(out)], capsys)  # the same command, without --resume
    assert code == 2 and stdout == "" and err.count("\n") == 1 and "--resume to continue it" in err, err
    code, stdout, err = run(["benchmark", *SMALL, "--out", str(out), "--resume", "--json"], capsys)
    assert code == 0, err
    assert "resuming: keeping 1 finished training run of 3 (maskable-ppo-seed0)" in err
    assert "training maskable-ppo seed 0 on 4" not in err and "training maskable-ppo seed 1 on 4" in err
    assert (out / "models" / "maskable-ppo-seed0.zip").read_bytes() == kept  # kept, not trained again
    assert _results(json.loads(stdout)) == _results(whole)


def test_resume_continues_the_same_settings_only(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "b"
    argv = [
        "benchmark",
        "--pool",
        POOL,
        "--train-count",
        "2",
        "--test-count",
        "2",
        "--validation-count",
        "2",
        "--sut",
        "scripted:replanner",
        "--out",
        str(out),
        "-q",
    ]
    assert run(argv, capsys)[0] == 0
    stored = json.loads((out / bench.CONFIG_FILE).read_text())
    assert stored["config"]["test_count"] == 2 and "workers" not in stored["config"]
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    code, stdout, err = run([*argv, "--resume", "--test-count", "3", "--seeds", "4"], capsys)
    assert code == 2 and stdout == "" and err.count("\n") == 1, err
    assert "--test-count 2 there, 3 here; --seeds 0 1 2 3 4 5 6 7 8 9 there, 4 here" in err
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before
    code, _, err = run([*argv, "--resume", "--force"], capsys)
    assert code == 2 and "give one of them" in err
    code, _, err = run([*argv, "--resume", "--workers", "2"], capsys)  # how many train at once: not a result's setting
    assert code == 0, err
    code, _, err = run(
        [
            "benchmark",
            "--pool",
            POOL,
            "--sut",
            "scripted:replanner",
            "--out",
            str(tmp_path / "new"),
            "--train-count",
            "2",
            "--test-count",
            "2",
            "--validation-count",
            "2",
            "--resume",
            "-q",
        ],
        capsys,
    )
    assert code == 0, err  # nothing to resume: it starts
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("mine")
    code, _, err = run([*argv[:-3], "--out", str(mine), "--resume"], capsys)
    assert code == 2 and "no benchmark to resume" in err and (mine / "notes.txt").read_text() == "mine"


def test_a_run_is_finished_only_with_its_whole_record_and_the_model_it_names(tmp_path: Path) -> None:
    config = bench.BenchmarkConfig(POOL, steps=1024)
    model = tmp_path / "models" / "maskable-ppo-seed0.zip"
    model.parent.mkdir()
    model.write_bytes(b"the model")
    resume.write_record(model, config, {"algo": "maskable-ppo", "seed": 0})
    assert resume.read_record(model, config) is not None
    assert resume.read_record(model, bench.BenchmarkConfig(POOL, steps=2048)) is None  # another configuration
    record = model.with_suffix(".json")
    text = record.read_text()
    record.write_text(text[: len(text) // 2])  # a partial record
    assert resume.read_record(model, config) is None
    record.write_text(text)
    model.write_bytes(b"another model")  # not the file recorded
    assert resume.read_record(model, config) is None
    model.unlink()
    assert resume.read_record(model, config) is None
    (tmp_path / "models" / ".maskable-ppo-seed1.123.456.tmp.zip").write_bytes(b"half")  # a killed worker's save
    assert resume.remove_temporaries(tmp_path) == 1 and not list((tmp_path / "models").glob(".*"))


def test_a_broken_model_is_refused_before_any_work(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--sut ppo:BROKEN`` scored the random floor (12 s on a standard pool) and wrote the
    pool before it loaded the file; now it is one line and no folder."""
    broken = tmp_path / "broken.zip"
    broken.write_bytes(b"PK\x03\x04 not a model at all" * 100)
    out = tmp_path / "b"
    code, stdout, err = run(["benchmark", "--pool", POOL, "--sut", f"ppo:{broken}", "--out", str(out)], capsys)
    assert code == 2 and stdout == "" and err.count("\n") == 1 and err.startswith(f"error: --sut ppo:{broken}"), err
    assert not out.exists()
    with pytest.raises(ProblemError, match="ppo:"):
        bench.benchmark(POOL, out, suts=(f"ppo:{broken}",))
    assert not out.exists()


def test_a_model_of_other_tests_is_refused_before_any_training(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A model trained on another observation size was a traceback after the training runs and
    the floor's scoring; now it is one line before them."""
    other = tmp_path / "other.zip"
    code = main(
        [
            "train",
            "small-reactive",
            "--steps",
            "128",
            "--num-envs",
            "8",
            "--n-steps",
            "16",
            "--net-arch",
            "16",
            "--eval-every",
            "0",
            "--eval-episodes",
            "0",
            "--device",
            "cpu",
            "--out",
            str(other),
            "-q",
        ]
    )
    assert code == 0
    capsys.readouterr()
    code, stdout, err = run(["benchmark", *SMALL, "--sut", f"ppo:{other}", "--out", str(tmp_path / "b")], capsys)
    assert code == 2 and stdout == "" and "Traceback" not in err, err
    assert err.splitlines()[-1].startswith(f"error: --sut ppo:{other} cannot play the pool's tests")
    assert "training" not in err and "scoring" not in err


@pytest.mark.slow
def test_a_benchmark_stopped_among_its_workers_resumes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """SIGTERM while two training processes run: the killed workers' temporary files are
    cleared, and ``--resume`` finishes with the table of an uninterrupted run."""
    assert SMALL[-4:-2] == ["--workers", "1"]
    argv = [*SMALL[:-4], "--workers", "2", *SMALL[-2:]]
    code, stdout, err = run(["benchmark", *argv, "--out", str(tmp_path / "whole"), "--json", "-q"], capsys)
    assert code == 0, err
    whole = json.loads(stdout)
    out = tmp_path / "stopped"
    proc = start_until([str(FLOWTEST), "benchmark", *argv, "--out", str(out)], "in 2 processes", signal.SIGTERM)
    proc.send_signal(signal.SIGTERM)
    try:
        proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:  # pragma: no cover
        proc.kill()
        raise
    code, stdout, err = run(["benchmark", *argv, "--out", str(out), "--resume", "--json"], capsys)
    assert code == 0, err
    assert _results(json.loads(stdout)) == _results(whole)
    assert not [p for p in out.rglob(".*") if ".tmp" in p.name]
