"""``flowtest benchmark``: its outputs, and that its numbers come from the runs.

Tiny pools (4x4 grids, a few tests) and a few hundred training steps keep these fast; the
real run and its figures are in docs/benchmarks.md.
"""

from __future__ import annotations

import json
import signal
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from agents.checkpoint import mark_own_file
from experiments import benchmark as bench
from experiments.benchmark import training_runs
from experiments.cli.cli import main
from experiments.evaluation.episodes import Trace
from flowtest_env.scoring import worst_share_mean
from synthesis.model.errors import ProblemError
from tests.testing_processes import start_until

pytest.importorskip("sb3_contrib")

FLOWTEST = Path(sys.executable).parent / "flowtest"
POOL = "safety2/4x4"
"""A pool whose tests build in a fraction of a second and that a random walk fails
(``G !p2``: it steps on the forbidden cell)."""


def run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """``main(argv)`` (a usage error exits through argparse) with stdout and stderr."""
    try:
        code = main(argv)
    except SystemExit as exc:
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    return code, out, err


def _system(doc: dict[str, Any], name: str) -> dict[str, Any]:
    return next(e for e in doc["systems"] if e["name"] == name)


def test_references_meet_every_test_and_random_does_not(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Without training: stdout is the JSON only; the replanner and GR(1) meet and realize
    on every test of both splits; a random system does not; the table's numbers are those
    of the report's runs (results.json), and every file is written."""
    out = tmp_path / "b"
    code, stdout, err = run(
        [
            "benchmark",
            "--pool",
            POOL,
            "--train-count",
            "6",
            "--test-count",
            "6",
            "--validation-count",
            "3",
            "--sut",
            "scripted:replanner",
            "--sut",
            "gr1",
            "random",
            "--out",
            str(out),
            "--json",
            "-q",
        ],
        capsys,
    )
    assert code == 0, err
    doc = json.loads(stdout)  # the whole of stdout is one JSON document
    assert stdout.count("\n") == 1 and err == ""
    assert doc["pool"] == POOL and doc["splits"]["train"]["count"] == 6 and doc["splits"]["test"]["seeds"] == [2_000_000, 2_000_005]
    for ref in ("scripted:replanner", "gr1"):
        e = _system(doc, ref)
        assert e["kind"] == "reference"
        for split in ("train", "test"):
            assert e[split]["met"]["mean"] == 1.0 and e[split]["realized"]["mean"] == 1.0
            assert e[split]["test_failures"] == 0
        assert e["gap"]["mean"] == 0.0
    rnd = _system(doc, "random")
    assert rnd["kind"] == "floor"  # the floor: 8 sampled runs per test, batched
    assert min(rnd["train"]["met"]["mean"], rnd["test"]["met"]["mean"]) < 1.0
    assert rnd["test"]["sampled"]["runs_per_test"] == 8 and rnd["test"]["greedy"] is None
    assert doc["headline"]["held_out_gap"] == {}  # no baseline trained
    # the scale: random is 0, the references 1 (the first that meets most defines it), in every replicate
    for split in ("train", "validation", "test"):
        assert doc["scale"][split]["floor"] == rnd[split]["met"]["mean"] and doc["scale"][split]["ceiling"] == 1.0
        assert doc["scale"][split]["ceiling_from"] == "scripted:replanner" and doc["scale"][split]["ceiling_is_bound"]
        gr1 = _system(doc, "gr1")[split]["greedy"]["normalized"]
        assert (gr1["point"], gr1["low"], gr1["high"]) == (1.0, 1.0, 1.0) and gr1["preliminary"]
        assert _system(doc, "scripted:replanner")[split]["greedy"]["normalized"]["defines"] == "ceiling"
        floor = rnd[split]["sampled"]["normalized"]
        assert (floor["point"], floor["low"], floor["high"]) == (0.0, 0.0, 0.0) and floor["defines"] == "floor"
        assert rnd[split]["headline_mode"] == "sampled" and _system(doc, "gr1")[split]["headline_mode"] == "greedy"
    # the per-run score matrices beside the table, as rliable reads them: one row per run, one column per test
    scores = np.load(out / "scores.npz")
    assert sorted(scores.files) == sorted(
        f"{s}/{m}/{n}" for s in ("train", "validation", "test") for m, n in (("sampled", "random"), ("greedy", "scripted:replanner"), ("greedy", "gr1"))
    )
    assert scores["test/sampled/random"].shape == (1, 6) and scores["validation/greedy/gr1"].shape == (1, 3)
    assert list(scores["test/sampled/random"][0]) == rnd["runs"][0]["test"]["sampled"]["per_test"]
    assert scores["test/sampled/random"].mean() == doc["scale"]["test"]["floor"]
    # the references' numbers are those of the report's runs (results.json); random's report runs are its
    # single-env runs (one per test), the table's its batched sampled runs
    records = json.loads((out / "results.json").read_text())
    assert {r["sut"] for r in records} == {"scripted:replanner", "gr1", "random"}
    for r in records:
        split = "train" if " train " in r["env"] else "test"
        assert r["episodes"] == 6
        if r["sut"] != "random":
            assert _system(doc, r["sut"])[split]["met"]["mean"] == pytest.approx(r["system_objective_met_rate"])
        for f in r["failures"]:  # a replay command per failing run, on that test's own file
            env = f["replay"].split("--env ")[1].split(" ")[0]
            assert Path(env).is_file() and Path(env).parent == (out / "pool" / split).resolve()
    for name in ("table.md", "table.json", "report.html", "report.md", ".flowtest-benchmark"):
        assert (out / name).is_file(), name
    assert not (out / "learning-curves.png").exists()  # no baseline, no curve
    assert len(list((out / "pool" / "train").glob("seed*.json"))) == 6
    md = (out / "table.md").read_text()
    assert (
        "| scripted:replanner | reference | 1 | 1 (reference) | 1 (reference) | 100.0 % (greedy) | 100.0 % | 100.0 % (greedy) | 100.0 % | 100.0 % | +0.0 pp |"
    ) in md
    rnd_tail = worst_share_mean(
        rnd["test"]["sampled"]["per_test"] if "per_test" in rnd["test"]["sampled"] else rnd["runs"][0]["test"]["sampled"]["per_test"], 0.1
    )
    assert f"| random | floor | 1 | 0 (floor) | – | {100 * rnd['test']['met']['mean']:.1f} % | – | {100 * rnd_tail:.1f} % |" in md
    # the header says what ran: nothing trained, the floor and the references scored
    assert doc["ran"]["trained"] == [] and doc["budget"] == {"steps_per_run": None, "training_runs": 0, "training_steps": 0}
    assert "**Trained**: nothing" in md and "1,000,000" not in md
    assert "matrix" in (out / "report.html").read_text()


def test_refuses_to_overwrite_without_force(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
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
    before = (out / "table.json").read_text()
    code, stdout, err = run(argv, capsys)
    assert code == 2 and stdout == "" and err.count("\n") == 1
    assert err.startswith("error: benchmark folder") and "--force" in err
    code, _, err = run(argv + ["--force"], capsys)
    assert code == 0, err
    assert json.loads((out / "table.json").read_text())["systems"] == json.loads(before)["systems"]
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("mine")
    code, _, err = run(argv[:-3] + ["--out", str(mine)], capsys)
    assert code == 2 and "already holds files" in err
    assert (mine / "notes.txt").read_text() == "mine"


@pytest.mark.parametrize(
    "argv, says",
    [
        (["--pool", "nonsense/5x5"], "unknown family"),
        (["--pool", "reaction2/5x4"], "not a square size"),
        (["--pool", POOL, "--sut", "scripted:nosuch"], "unknown scripted SUT"),
        (["--pool", POOL, "--sut", "nosuch"], "unknown policy"),
        (["--pool", POOL, "--sut", "ppo", "--steps", "0"], "positive integer"),
        (["--pool", POOL, "--sut", "ppo", "--algo", "dqn"], "invalid choice"),
    ],
)
def test_bad_input_is_one_error_line(tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], says: str) -> None:
    out = tmp_path / "b"
    code, stdout, err = run(["benchmark", *argv, "--out", str(out)], capsys)
    assert code == 2 and stdout == ""
    assert err.count("\n") == 1 and err.startswith("error: ") and says in err, err
    assert not out.exists()  # refused before any work or file


def test_metrics_and_confidence_intervals_from_runs() -> None:
    """The table's numbers are computed from the runs' verdicts."""

    def trace(outcome: str, realized: bool, restrictions: int, steps: int) -> Trace:
        t = Trace("t.json", "s", 0)
        t.verdict = {"system_objective": outcome, "test_objective_realized": realized, "restrictions": restrictions, "steps": steps}
        return t

    m = bench.split_metrics([trace("met", True, 2, 10), trace("met", True, 4, 20), trace("violated", False, 0, 5), trace("open", False, 6, 100)])
    assert m["met"] == 0.5 and m["realized"] == 1.0 and m["restrictions"] == 3.0 and m["steps"] == 15.0
    assert (m["violated"], m["open"], m["tests"]) == (1, 1, 4)
    none = bench.split_metrics([trace("open", False, 1, 100)])
    assert none["met"] == 0.0 and none["realized"] is None and none["steps"] is None
    s = bench.mean_ci([0.5, 0.7])
    assert s["mean"] == pytest.approx(0.6) and s["ci95"] == pytest.approx(12.7062 * 0.1 / 1.0, rel=1e-4)
    assert bench.mean_ci([0.3])["ci95"] is None and bench.mean_ci([None])["mean"] is None
    three = bench.mean_ci([1.0, 0.0, 0.5, None])
    assert three["mean"] == pytest.approx(0.5) and three["ci95"] == pytest.approx(4.3027 * 0.5 / 3**0.5, rel=1e-4)


@pytest.mark.parametrize("algo", ["maskable-ppo", "recurrent-ppo"])
def test_batch_evaluation_gives_the_single_env_verdicts(tmp_path: Path, algo: str) -> None:
    """The learning curves' batch evaluation (one PoolVectorEnv, every test at once) gives
    exactly the verdicts of the single env that scores the systems and replays their runs,
    with the memory wrapper (MaskablePPO) and with an LSTM state (RecurrentPPO)."""
    from experiments.training.system import make_model, make_training_vec_env

    config = bench.BenchmarkConfig(POOL, suts=("ppo",), algos=(algo,), train_count=5, test_count=5, validation_count=2)
    splits = bench.load_splits(config, tmp_path, progress=False)
    settings = bench.baseline_settings(algo, "sb3")
    env = make_training_vec_env(bench.POOL_ENV_ID, 0, {**settings, "n_envs": 1}, {"pool": POOL, "split": "train", "count": 5})
    model = make_model(env, settings, 3)  # untrained: a fixed, arbitrary deterministic policy
    path = tmp_path / "m.zip"
    model.save(str(path))
    mark_own_file(path)  # written by this test: scored without --trust-model
    for split in splits.values():
        games, budgets = bench.games_and_budgets(split)
        batch = bench.batch_verdicts(model, games, settings["memory"], budgets)
        single = bench.score_systems([f"ppo:{path}"], split)[f"ppo:{path}"]
        for key in ("system_objective", "test_objective_realized", "restrictions", "steps"):
            assert list(batch[key]) == [t.verdict[key] for t in single], key


@pytest.mark.parametrize("select", ["validation", "final"])
def test_baselines_train_and_are_scored(tmp_path: Path, capsys: pytest.CaptureFixture[str], select: str) -> None:
    """A tiny end-to-end run with training: a model and a curve per seed; the model scored is
    the curve point with the best validation met (the latest of equals; ``--select final``:
    the last point), whose train and validation met equal the batched greedy score of the
    scored model; the gap is train minus held-out per seed, the generalization curve has a
    point per training-set size, and the figures and the report are written."""
    out = tmp_path / "b"
    code, stdout, err = run(
        [
            "benchmark",
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
            "--algo",
            "maskable-ppo",
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
            "--runs",
            "2",
            "--select",
            select,
            "--out",
            str(out),
            "-q",
        ],
        capsys,
    )
    assert code == 0, err
    assert "held-out normalized score, sampled (0 = random, 1 = reference): maskable-ppo" in stdout
    doc = json.loads((out / "table.json").read_text())
    e = _system(doc, "maskable-ppo")
    assert e["kind"] == "baseline" and [r["seed"] for r in e["runs"]] == [0, 1]
    for run_, training in zip(e["runs"], e["training"], strict=True):
        assert Path(training["model"]).is_file() and run_["sut"] == f"ppo:{training['model']}"
        steps = [p[0] for p in training["curve"]]
        assert steps[0] == 0 and steps[-1] == training["steps"] == 1024
        if select == "validation":
            val = [p[2] for p in training["curve"]]
            kept = max(i for i, v in enumerate(val) if v == max(val))  # the latest of the best
            assert training["selected_step"] == steps[kept]
        else:
            kept = len(steps) - 1
            assert training["selected_step"] is None
        assert training["curve"][kept][1:] == [run_["train"]["met"], run_["validation"]["met"]]
        assert run_["gap"] == pytest.approx(run_["train"]["greedy"]["met"] - run_["test"]["greedy"]["met"])
        assert run_["test"]["sampled"]["runs"] == 2 and run_["test"]["greedy"]["runs"] == 1
        assert run_["test"]["headline_mode"] == "sampled" and run_["test"]["met"] == run_["test"]["sampled"]["met"]
        assert run_["train"]["headline_mode"] == "greedy"  # the train split is played greedily only
    assert e["gap"]["mean"] == pytest.approx(np.mean([r["gap"] for r in e["runs"]]))
    assert doc["headline"]["held_out_gap"]["maskable-ppo"] == e["gap"]
    assert doc["headline"]["mode"] == "sampled"
    assert doc["headline"]["normalized_held_out"]["maskable-ppo"] == {
        "headline_mode": "sampled",
        "greedy": e["test"]["greedy"]["normalized"],
        "sampled": e["test"]["sampled"]["normalized"],
    }
    assert doc["headline"]["tail_held_out"]["maskable-ppo"] == e["test"]["sampled"]["tail"]
    assert e["test"]["sampled"]["normalized"]["preliminary"] and e["test"]["sampled"]["normalized"]["statistic"] == "mean"
    curve = doc["generalization"]
    assert [p["train_tests"] for p in curve] == [2, 4] and [p["seeds"] for p in curve] == [[0], [0, 1]]
    assert curve[-1]["greedy"] == e["test"]["greedy"]["normalized"]  # the last point is the main runs
    assert doc["budget"] == {"steps_per_run": 1024, "training_runs": 3, "training_steps": 3 * 1024}
    (trained,) = doc["ran"]["trained"]
    kept_steps = [t["selected_step"] if select == "validation" else t["steps"] for t in e["training"]]
    assert {k: v for k, v in trained.items() if k != "plateau"} == {
        "algo": "maskable-ppo",
        "seeds": [0, 1],
        "steps": 1024,
        "train_tests": 4,
        "trainer": "native",
        "select": select,
        "selected_steps": kept_steps,
    }
    assert trained["plateau"]["runs"] == 2 and trained["plateau"]["validation_tests"] == 2
    assert doc["ran"]["curve"] == [{"train_tests": 2, "seeds": [0]}]
    md = (out / "table.md").read_text()
    assert "**Trained**: maskable-ppo, seeds 0, 1 (2 runs), 1,024 time steps each on the first 4 train tests" in md
    chosen = "checkpoint with the best greedy met on the validation tests is scored" if select == "validation" else "final model of every run is scored"
    assert chosen in md and "validation plateau: the last evaluation gained" in md
    assert np.load(out / "scores.npz")["test/sampled/maskable-ppo"].shape == (2, 3)
    assert (out / "learning-curves.png").stat().st_size > 10_000
    assert (out / "generalization.png").stat().st_size > 10_000
    assert len(list((out / "models").glob("*.zip"))) == 3


@pytest.mark.slow
def test_same_seeds_same_table(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Deterministic given seeds: two runs give the same numbers and curves (only the
    times and paths differ), whether the training runs go one at a time or in two processes."""
    docs = []
    for name, workers in (("a", "2"), ("b", "1")):
        code, stdout, err = run(
            [
                "benchmark",
                "--pool",
                POOL,
                "--train-count",
                "3",
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
                workers,
                "--out",
                str(tmp_path / name),
                "--json",
                "-q",
            ],
            capsys,
        )
        assert code == 0, err
        docs.append(json.loads(stdout))
    for doc in docs:
        for e in doc["systems"]:
            for r in e["runs"]:
                r.pop("sut")
            for t in e.get("training", []):
                t.pop("seconds"), t.pop("curve_seconds"), t.pop("model")
    assert docs[0]["systems"] == docs[1]["systems"]
    assert docs[0]["generalization"] == docs[1]["generalization"]


def test_ctrl_c_during_training(tmp_path: Path) -> None:
    """SIGINT while a baseline trains: exit 130 within 2 s, one line, nothing on stdout."""
    proc = start_until(
        [
            str(FLOWTEST),
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
            "ppo",
            "--algo",
            "recurrent-ppo",
            "--steps",
            "100000",
            "--out",
            str(tmp_path / "b"),
            "--json",
        ],
        "training recurrent-ppo",
        signal.SIGINT,
    )
    time.sleep(1.0)
    t0 = time.perf_counter()
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert time.perf_counter() - t0 < 2.0
    assert out == "" and "Traceback" not in err
    assert err.splitlines()[-1] == "flowtest: interrupted"


def test_a_python_policy_is_scored_by_the_protocol(tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """``--sut python:MODULE:NAME``: a batched policy (its loader marked ``batched = True``,
    agents.batched) plays every test in one batch, a planner function through the single env;
    both get the protocol's numbers (met, normalized with the split's floor and ceiling)."""
    (tmp_path / "mine.py").write_text(
        "import numpy as np\n\n"
        "class FirstLegal:\n"
        "    batched = True\n\n"
        "    def act(self, observations, masks, deterministic):\n"
        "        return np.argmax(masks, axis=1)\n\n"
        "first_legal = FirstLegal\n\n"
        "def planner(observation, mask):\n"
        "    return int(np.argmax(mask))\n"
    )
    monkeypatch.chdir(tmp_path)
    code, stdout, err = run(
        [
            "benchmark",
            "--pool",
            POOL,
            "--train-count",
            "3",
            "--test-count",
            "4",
            "--validation-count",
            "2",
            "--sut",
            "python:mine:first_legal",
            "python:mine:planner",
            "--out",
            str(tmp_path / "b"),
            "--json",
            "-q",
            "--bootstrap",
            "50",
        ],
        capsys,
    )
    assert code == 0, err
    doc = json.loads(stdout)
    batched, single = _system(doc, "python:mine:first_legal"), _system(doc, "python:mine:planner")
    assert {e["name"] for e in doc["systems"]} == {"random", "scripted:replanner", "gr1", "python:mine:first_legal", "python:mine:planner"}
    for split in ("train", "validation", "test"):  # the same deterministic choice, batched or one env at a time
        assert batched[split]["greedy"]["met"]["mean"] == single[split]["greedy"]["met"]["mean"]
        assert batched[split]["greedy"]["runs_per_test"] == 1
        if split == "test":  # sampled on the held-out tests, through the same act: a fixed rule samples itself
            assert batched[split]["sampled"]["runs_per_test"] == 8
            assert batched[split]["sampled"]["met"]["mean"] == batched[split]["greedy"]["met"]["mean"]
        else:
            assert batched[split]["sampled"] is None
        n = batched[split]["greedy"]["normalized"]
        scale = doc["scale"][split]
        want = (batched[split]["met"]["mean"] - scale["floor"]) / (scale["ceiling"] - scale["floor"])
        assert n["point"] == pytest.approx(want) and n["low"] <= n["point"] <= n["high"]
        assert n["preliminary"] and n["statistic"] == "mean" and n["seed_se"] is None  # one seed: the tests' error only
    # a --sut-only run: its header says that nothing was trained and what was only scored, and how many seeds each
    assert doc["ran"]["trained"] == [] and doc["budget"]["steps_per_run"] is None
    assert {s["name"]: s["seeds"] for s in doc["ran"]["scored"]}["python:mine:first_legal"] == 1
    md = (tmp_path / "b" / "table.md").read_text()
    assert "**Trained**: nothing" in md and "time steps" not in md
    assert "`python:mine:first_legal` (1 seed: greedy and sampled, 8 sampled runs per test)" in md and "`python:mine:planner` (1 seed: greedy)" in md
    assert set(doc["headline"]["normalized_held_out"]) == {"python:mine:first_legal", "python:mine:planner"}


def test_a_standard_pool_id_is_accepted_and_the_command_reruns_the_config() -> None:
    """``--pool reachability1/5x5-v1`` (a standard pool, shipped records) passes the checks
    like an on-demand name; the results file's command spells out every setting that is not
    the default."""
    config = bench.BenchmarkConfig("reachability1/5x5-v1", suts=("scripted:replanner",))
    bench.check_config(config)  # no error
    with pytest.raises(ProblemError, match="not a standard pool"):
        bench.check_config(bench.BenchmarkConfig("nosuch1/5x5-v1"))
    assert bench.command_of(bench.BenchmarkConfig(POOL)) == f"flowtest benchmark --pool {POOL} --out OUT"
    small = bench.BenchmarkConfig(POOL, seeds=(0, 1), steps=5000, curve_sizes=(), algos=("plr-ppo",))
    assert bench.command_of(small) == (f"flowtest benchmark --pool {POOL} --algo plr-ppo --steps 5000 --seeds 0 1 --curve-sizes --out OUT")


def test_the_defaults_take_a_standard_pools_whole_smaller_split(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """The test-agent pool ships 250 held-out tests (a family that builds slowly); with the
    default counts the benchmark scores all 250 of them instead of asking for 1,000 (the other
    750 would be synthesized on demand, for hours); a count given is kept, and the command in
    the results file spells the count out."""
    agent = "reachability1/5x5/blocked/agent-v1"
    assert bench.default_counts(agent) == {"train": 4096, "validation": 256, "test": 250}
    assert bench.default_counts(POOL) == bench.BenchmarkConfig(POOL).counts()
    # from Python as from the command line
    assert bench.BenchmarkConfig.for_pool(agent).counts() == {"train": 4096, "validation": 256, "test": 250}
    assert bench.BenchmarkConfig.for_pool(agent, test_count=1000, runs=2).test_count == 1000
    assert bench.BenchmarkConfig.for_pool(agent, test_count=None).test_count == 250
    assert bench.BenchmarkConfig.for_pool(POOL) == bench.BenchmarkConfig(POOL)
    seen: list[bench.BenchmarkConfig] = []

    def stop(config: bench.BenchmarkConfig) -> None:
        seen.append(config)
        raise ProblemError("stopped here")

    monkeypatch.setattr(bench, "check_config", stop)
    assert main(["benchmark", "--pool", agent, "--out", str(tmp_path / "a")]) == 2
    assert main(["benchmark", "--pool", agent, "--test-count", "100", "--out", str(tmp_path / "b")]) == 2
    assert [c.counts() for c in seen] == [{"train": 4096, "validation": 256, "test": 250}, {"train": 4096, "validation": 256, "test": 100}]
    assert "--test-count 250" in bench.command_of(seen[0])


def test_curve_sizes_not_below_the_train_count_are_said_to_be_left_out(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    def stop(config: bench.BenchmarkConfig, *args: object, **kwargs: object) -> None:
        raise ProblemError("stopped here")

    monkeypatch.setattr(bench, "run_benchmark", stop)
    assert main(["benchmark", "--pool", POOL, "--train-count", "4", "--curve-sizes", "2", "16", "32", "--out", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err
    assert "flowtest: warning: curve sizes 16 32 (--curve-sizes) are above --train-count 4: left out" in err
    assert main(["benchmark", "--pool", POOL, "--train-count", "4", "--curve-sizes", "2", "4", "--out", str(tmp_path / "b")]) == 2
    assert "warning" not in capsys.readouterr().err  # the train count itself is on the curve


def test_sb3_trains_on_the_standard_pools_shipped_records(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """With ``--trainer sb3`` on a standard pool the training envs load its shipped records
    (the id itself), not the on-demand pool of the same seeds, which synthesized every test
    again (2 min 20 s for 1,024 tests where the records load in seconds)."""
    asked: dict[str, Any] = {}

    class Stop(Exception):
        pass

    def capture(env_id: str, seed: int, settings: dict[str, Any], pool_options: dict[str, Any]) -> None:
        asked.update(pool_options)
        raise Stop

    monkeypatch.setattr(training_runs, "make_training_vec_env", capture)
    config = bench.BenchmarkConfig("reachability1/5x5-v1", trainer="sb3", train_count=16)
    with pytest.raises(Stop):
        bench.train_baseline(config, "maskable-ppo", 0, {}, tmp_path, train_tests=16)
    assert asked == {"pool": "reachability1/5x5-v1", "split": "train", "count": 16}


def test_a_system_of_several_seeds_gets_the_seed_and_test_interval() -> None:
    """A system given as it is, with one run per seed from any source (say five checkpoints
    of one method), gets the statistics of a trained baseline: 5 seeds, so the IQM and the
    seed-and-test bootstrap; it is in the headline, and the header counts its seeds."""
    config = bench.BenchmarkConfig(POOL, suts=("ppo:runs/*.zip",), train_count=4, validation_count=2, test_count=6, bootstrap=200, runs=2)
    splits = {n: bench.Split(n, n, [10 * i, 10 * i + 5], []) for i, n in enumerate(bench.SPLIT_NAMES)}
    rng = np.random.default_rng(0)

    def metrics(per_test: list[float], runs: int) -> dict[str, Any]:
        return {
            "tests": len(per_test),
            "runs": runs,
            "met": float(np.mean(per_test)),
            "realized": 1.0,
            "restrictions": 0.0,
            "steps": 4.0,
            "violated": 0,
            "open": 0,
            "test_failures": 0,
            "per_test": per_test,
        }

    def row(seed: int | None, greedy: list[float] | None, sampled: list[float] | None) -> dict[str, Any]:
        return {
            "seed": seed,
            "sut": "x",
            **{s: {"greedy": greedy and metrics(greedy, 1), "sampled": sampled and metrics(sampled, 2)} for s in bench.SPLIT_NAMES},
        }

    mine = [row(k, [float(v) for v in rng.integers(0, 2, 6)], [v / 2 for v in rng.integers(0, 3, 6)]) for k in range(5)]
    systems = [
        bench.SystemRuns("ppo:runs/*.zip", "system", mine),
        bench.SystemRuns("random", "floor", [row(None, None, [0.5, 0.5, 0, 0, 0.5, 0])]),
        bench.SystemRuns("gr1", "reference", [row(None, [1.0] * 6, None)]),
    ]
    doc = bench.benchmark_table(config, splits, systems, [])
    n = doc["headline"]["normalized_held_out"]["ppo:runs/*.zip"]["sampled"]
    assert n["statistic"] == "iqm" and n["interval"] == "seed-and-test bootstrap" and not n["preliminary"] and n["seeds"] == 5
    assert n["low"] <= n["point"] <= n["high"]
    assert doc["ran"]["trained"] == [] and doc["ran"]["scored"][0] == {
        "name": "ppo:runs/*.zip",
        "kind": "system",
        "seeds": 5,
        "modes": ["greedy", "sampled"],
        "runs_per_test": 2,
    }
    md = bench.table_markdown({**doc, "seconds": {}, "outputs": {}})
    assert "`ppo:runs/*.zip` (5 seeds: greedy and sampled, 2 sampled runs per test)" in md
    assert "| ppo:runs/*.zip | system | 5 |" in md


def test_the_counting_memory_baseline_trains_and_plays_with_its_memory(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--algo counts-ppo``: masked PPO with ``memory="counts"``, trained and scored under that
    memory (its summary's settings, and the saved model's own record of it); refused with
    ``--trainer sb3``."""
    assert bench.baseline_settings("counts-ppo")["memory"] == "counts"
    code, stdout, err = run(
        ["benchmark", "--pool", POOL, "--algo", "counts-ppo", "--seeds", "0", "--steps", "2048", "--train-count", "4", "--validation-count", "2",
         "--test-count", "4", "--curve-seeds", "0", "--out", str(tmp_path / "b"), "--json", "-q", "--bootstrap", "50"],
        capsys,
    )  # fmt: skip
    assert code == 0, err
    counts = _system(json.loads(stdout), "counts-ppo")
    assert counts["settings"]["memory"] == "counts" and counts["test"]["sampled"]["runs_per_test"] == 8
    from agents.native_ppo import load_native

    assert load_native(tmp_path / "b" / "models" / "counts-ppo-seed0.zip").flowtest_memory == "counts"
    code, _, err = run(["benchmark", "--pool", POOL, "--algo", "counts-ppo", "--trainer", "sb3", "--out", str(tmp_path / "c")], capsys)
    assert code == 2 and "--algo counts-ppo: a baseline of the native trainer only" in err


def test_the_plateau_counts_runs_whose_last_gain_exceeds_the_validation_half_width() -> None:
    """A run is still rising when its last evaluation gained more than a met share's 95 %
    half-width on the validation tests (1.96 sqrt(p (1 - p) / n) at its last share); the
    row's text says so, and a run with one evaluation counts for nothing."""
    from experiments.benchmark.table import selection_text, validation_plateau

    half = 1.96 * np.sqrt(0.5 * 0.5 / 100)  # 9.8 pp at p = 0.5 on 100 tests
    p = validation_plateau([[0.0, 0.45, 0.5], [0.0, 0.3, 0.5], [0.5]], 100)
    assert p is not None and p["runs"] == 2 and p["rising"] == 1
    assert p["median_half_width"] == pytest.approx(half) and p["median_last_gain"] == pytest.approx((0.05 + 0.2) / 2)
    assert validation_plateau([[0.5], []], 100) is None
    flat = validation_plateau([[0.0, 0.49, 0.5]] * 3, 100)
    assert flat is not None and flat["rising"] == 0
    t = {"algo": "maskable-ppo", "steps": 1000, "select": "validation", "selected_steps": [1000, 600, 1000], "plateau": flat}
    text = selection_text(t)
    assert "selected at the final evaluation in 2 of 3 runs; earlier at steps 600" in text and "at its plateau" in text
    assert "still rising in 1 of 2 runs" in selection_text({**t, "plateau": p})
    assert "final model of every run is scored (no model selection)" in selection_text({"algo": "x", "steps": 1})


def test_sb3_baselines_are_scored_at_their_checkpoint_chosen_by_validation(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--trainer sb3`` with the default ``--select validation``: the run saves its best
    validation checkpoint while it trains and scores that one, without ``--trust-model`` (the
    run wrote it), and its train and validation met are the curve's at the kept step."""
    out = tmp_path / "s"
    argv = ["benchmark", "--pool", POOL, "--trainer", "sb3", "--sut", "ppo", "--train-count", "4", "--validation-count", "2"]
    argv += ["--test-count", "2", "--train-eval-count", "4", "--steps", "2048", "--seeds", "0", "--curve-sizes", "2"]
    argv += ["--curve-seeds", "1", "--curve-points", "2", "--runs", "2", "--parallel", "serial", "--out", str(out), "-q"]
    code, _, err = run(argv, capsys)
    assert code == 0, err
    e = _system(json.loads((out / "table.json").read_text()), "maskable-ppo")
    (training,), (run_,) = e["training"], e["runs"]
    val = [p[2] for p in training["curve"]]
    kept = max(i for i, v in enumerate(val) if v == max(val))
    assert training["selected_step"] == training["curve"][kept][0]
    assert training["curve"][kept][1:] == [run_["train"]["met"], run_["validation"]["met"]]
