"""Outputs never follow a link, faults are one line, files are bounded before they are read.

The cases of the hostile battery about the file system: a symbolic link inside an output
folder (``OUT/traces`` pointing at the user's pictures), the cache folder missing, a
file, unwritable or full, a cache entry that is a folder, a problem file name of 250
characters, a 100 MB file passed as a test, SIGTERM in the middle of a run. Each keeps
the contract: nothing of the user's is overwritten, one ``error:`` line or one warning,
no temporary file left behind, exit 130 as for Ctrl-C.
"""

from __future__ import annotations

import errno
import os
import shutil
import signal
import subprocess
import sys
import time
import tracemalloc
from pathlib import Path
from typing import Any

import gymnasium as gym
import pytest

import flowtest_env
import flowtest_env.random_grid as rg
from experiments.cli.cli import main as cli_main
from experiments.outputs import output_subfolder, prepare_output_folder, write_atomically
from flowtest_env import sources
from synthesis.artifacts.artifact import TestArtifact
from synthesis.model.errors import ProblemError
from tests.testing_artifacts import played_artifact

DATA = Path(__file__).resolve().parents[1] / "data"
ROOT = Path(__file__).resolve().parents[2]
FLOWTEST = Path(sys.executable).parent / "flowtest"


def _problem(tmp_path: Path, name: str = "mine") -> Path:
    p = tmp_path / f"{name}.toml"
    shutil.copy(DATA / "ok_grid.toml", p)
    return p


def _tmp_files(folder: Path) -> list[Path]:
    return [p for p in folder.rglob("*") if ".tmp" in p.name] if folder.exists() else []


# ------------------------------------------------------ break 2: links inside output folders


def test_a_linked_subfolder_of_an_output_folder_is_never_written_through(tmp_path: Path) -> None:
    out, user = tmp_path / "OUT", tmp_path / "user"
    user.mkdir()
    (user / "keep.png").write_text("the user's picture")
    prepare_output_folder(out, ".flowtest-test", False, "report folder")
    (out / "traces").symlink_to(user, target_is_directory=True)
    with pytest.raises(ProblemError, match="symbolic link"):
        write_atomically(out / "traces" / "keep.png", lambda tmp: tmp.write_text("FlowTest's picture"))
    with pytest.raises(ProblemError, match="symbolic link"):
        output_subfolder(out, "traces")
    with pytest.raises(ProblemError, match="symbolic link"):  # a second run is refused before any work
        prepare_output_folder(out, ".flowtest-test", True, "report folder")
    assert (user / "keep.png").read_text() == "the user's picture" and sorted(os.listdir(user)) == ["keep.png"]


def test_a_link_deeper_inside_an_output_folder_is_refused(tmp_path: Path) -> None:
    out, user = tmp_path / "OUT", tmp_path / "user"
    (user / "b").mkdir(parents=True)
    prepare_output_folder(out, ".flowtest-test", False, "benchmark folder")
    (out / "models").mkdir()
    (out / "models" / "a").symlink_to(user, target_is_directory=True)
    with pytest.raises(ProblemError, match="symbolic link"):
        write_atomically(out / "models" / "a" / "b" / "model.zip", lambda tmp: tmp.write_bytes(b"x"))
    assert list((user / "b").iterdir()) == []
    write_atomically(out / "pool" / "x" / "test.json", lambda tmp: tmp.write_text("{}"))  # real folders are made
    assert (out / "pool" / "x" / "test.json").read_text() == "{}"


def test_flowtest_evaluate_never_overwrites_through_a_linked_traces_folder(
    tmp_path: Path, cache: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    args = ["evaluate", "--env", "small-reactive", "--sut", "random", "--episodes", "1", "--out", "OUT", "-q"]
    assert cli_main(args) == 0
    pictures = sorted(p.name for p in (tmp_path / "OUT" / "traces").iterdir())
    assert pictures
    user = tmp_path / "user"
    user.mkdir()
    for name in pictures:
        (user / name).write_text("the user's own")
    shutil.rmtree(tmp_path / "OUT" / "traces")
    (tmp_path / "OUT" / "traces").symlink_to(user, target_is_directory=True)
    capsys.readouterr()
    code = cli_main(args)
    err = capsys.readouterr().err
    assert code == 2 and err.count("error:") == 1 and "symbolic link" in err, err
    assert all((user / name).read_text() == "the user's own" for name in pictures)


# ------------------------------------------------------------- break 9: cache faults


def _fault_case(tmp_path: Path, cache: Path, how: str) -> None:
    if how == "a file":
        cache.parent.mkdir(parents=True, exist_ok=True)
        cache.write_text("not a folder")
    elif how == "an entry that is a folder":
        raw = _problem(tmp_path).read_bytes()
        sources.problem_cache_path(_problem(tmp_path), raw).mkdir(parents=True)
    elif how == "not creatable":
        os.environ["FLOWTEST_CACHE_DIR"] = "/proc/flowtest-cache-cannot-exist"
    elif how == "read-only":
        if os.geteuid() == 0:
            pytest.skip("root writes into a read-only folder; 'not creatable' covers the fault as root")
        cache.mkdir(parents=True)
        cache.chmod(0o500)


@pytest.mark.parametrize("how", ["a file", "an entry that is a folder", "not creatable", "read-only"])
def test_a_faulty_cache_is_a_warning_and_the_test_is_kept_in_memory(tmp_path: Path, cache: Path, how: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("FLOWTEST_CACHE_DIR", str(cache))  # restored after the test, whatever the case sets
    _fault_case(tmp_path, cache, how)
    with pytest.warns(UserWarning, match="kept in memory"):
        env = gym.make("FlowTest-v0", test=str(_problem(tmp_path)))
    assert played_artifact(env).name == "ok-grid"
    assert _tmp_files(cache) == [] and _tmp_files(tmp_path) == []


def test_a_full_cache_leaves_no_temporary_file(tmp_path: Path, cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def full(self: TestArtifact, path: Any) -> None:
        Path(path).write_text('{"half": ')  # part of the entry written, then the disk is full
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(TestArtifact, "save", full)
    with pytest.warns(UserWarning, match="No space left on device.*kept in memory"):
        art = flowtest_env.load_test(_problem(tmp_path))
    assert art.name == "ok-grid"
    assert _tmp_files(cache) == [] and list((cache / "problems").iterdir()) == []


def test_a_250_character_problem_file_name_is_cached_under_a_short_name(tmp_path: Path, cache: Path) -> None:
    p = _problem(tmp_path, "p" * 250)
    art = flowtest_env.load_test(p)
    assert art.name == "ok-grid"
    (entry,) = (cache / "problems").iterdir()
    assert len(entry.name) < 100
    sources._LOADED.clear()
    assert flowtest_env.load_test(p).name == "ok-grid"


def test_a_pool_cache_that_is_a_file_is_a_warning(tmp_path: Path, cache: Path) -> None:
    cache.parent.mkdir(parents=True, exist_ok=True)
    cache.write_text("not a folder")
    with pytest.warns(UserWarning, match="kept in memory"):
        (art,) = rg.build_pool(5, "reachability", 1, [0])
    assert art.summary["flow"] >= 1 and _tmp_files(tmp_path) == []


# ------------------------------------------------- break 7: bounded before it is read


@pytest.mark.parametrize("suffix", [".json", ".toml"])
def test_a_huge_test_file_is_refused_before_it_is_read(tmp_path: Path, cache: Path, suffix: str) -> None:
    big = tmp_path / f"big{suffix}"
    with open(big, "wb") as f:
        f.truncate(100 * 2**20)  # sparse: 100 MiB on paper, nothing on disk
    tracemalloc.start()
    try:
        t0 = time.perf_counter()
        with pytest.raises(ProblemError, match="larger than 16 MiB"):
            gym.make("FlowTest-v0", test=str(big))
        elapsed = time.perf_counter() - t0
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 4 * 2**20, f"{peak} bytes read before the refusal"
    assert elapsed < 1.0


def test_a_huge_env_file_is_one_error_line_from_flowtest_train(tmp_path: Path, cache: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("torch")
    big = tmp_path / "big.json"
    with open(big, "wb") as f:
        f.truncate(100 * 2**20)
    code = cli_main(["train", str(big), "--out", str(tmp_path / "m.zip")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("error:") == 1 and "larger than 16 MiB" in err, err


# -------------------------------------------------------- break 13: SIGTERM is Ctrl-C


# (the SIGTERM twin of Ctrl-C on the console script: tests/experiments/test_cli.py test_ctrl_c_on_the_console_script)


@pytest.mark.slow
def test_sigterm_while_a_report_is_written_leaves_no_hidden_file(tmp_path: Path) -> None:
    """SIGTERM at several moments of ``flowtest evaluate``: exit 130 (or 0 if it had
    finished), never a ``.tmp`` file in the report folder."""
    for k, delay in enumerate((0.3, 2.0, 4.0, 5.0, 6.0, 7.0)):
        out = tmp_path / f"OUT{k}"
        proc = subprocess.Popen(
            [str(FLOWTEST), "evaluate", "--env", "small-reactive", "maze2", "--sut", "random", "--episodes", "30", "--out", str(out), "-q"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            cwd=tmp_path,
            preexec_fn=lambda: signal.signal(signal.SIGTERM, signal.SIG_DFL),
        )
        time.sleep(delay)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
        assert proc.returncode in (0, 130), err
        assert "Traceback" not in err
        assert _tmp_files(out) == [], (delay, _tmp_files(out))


# ------------------------------------------------ a truncated shipped pool file (issue 43)


@pytest.mark.parametrize("pool_id", ["reachability1/5x5-v1", "reachability1/5x5-v2"])
def test_a_truncated_shipped_pool_file_is_one_line_naming_the_file_and_the_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], pool_id: str
) -> None:
    """A copy of the records cut short was a bare ``EOFError`` traceback (from the line count,
    for a ``-v1`` pool) or a line without the place; now one ``error:`` line with the file and
    the line where it stops."""
    import flowtest_env.standard_pools as sp
    from tests.testing_pools import REAL_DATA, empty_data

    data = empty_data(tmp_path, monkeypatch)
    pool = sp.standard_pool(pool_id)
    raw = (REAL_DATA / pool.slug / "train.jsonl.gz").read_bytes()
    cut = data / pool.slug / "train.jsonl.gz"
    cut.parent.mkdir(parents=True)
    cut.write_bytes(raw[: len(raw) // 3])
    code = cli_main(
        [
            "benchmark",
            "--pool",
            pool_id,
            "--sut",
            "scripted:replanner",
            "--train-count",
            "2",
            "--validation-count",
            "2",
            "--test-count",
            "2",
            "--out",
            str(tmp_path / "b"),
            "-q",
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and err.startswith("error: ") and f"{cut}, line " in err, err
    assert "the file stops in the middle" in err and "Traceback" not in err and "EOFError" not in err
    line = int(err.split(", line ")[1].split(":")[0])
    assert 1 < line <= 4096  # where the copy stops, inside the file
    with pytest.raises(ProblemError, match=r"train\.jsonl\.gz, line \d+: the file stops in the middle"):
        pool.shipped("train")
