"""Training logs are outputs (issue 43, item 3): ``flowtest train --log-dir`` never writes
through a symbolic link, never over a user's file nor an earlier run's logs, and a run that
ends before it logged anything leaves nothing behind.

Each run gets a new folder inside ``--log-dir`` named after its model (``logs/m1``, or
``logs/m1-2`` when taken), as TensorBoard users keep one folder per run.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from experiments.cli.cli import main
from experiments.outputs import new_run_folder, run_log_folder
from synthesis.model.errors import ProblemError

pytest.importorskip("torch")

TINY = ["--steps", "256", "--num-envs", "8", "--n-steps", "16", "--net-arch", "16", "--eval-every", "0", "--eval-episodes", "0", "--device", "cpu", "-q"]
"""One rollout of a tiny network: a run in about a second."""


def _train(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    try:
        code = main(["train", "small-reactive", *TINY, *argv])
    except SystemExit as exc:
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    return code, out, err


def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_a_second_run_never_replaces_the_first_runs_logs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The hostile battery's data loss: a second ``flowtest train ... --log-dir logs`` replaced
    the first run's ``logs/progress.csv``. Now each run has its own folder, the first run's
    files stay byte for byte, with another model and with the same one under ``--force``."""
    logs = tmp_path / "logs"
    code, out, err = _train(capsys, "--out", str(tmp_path / "m1.zip"), "--log-dir", str(logs))
    assert code == 0, err
    first = _files(logs)
    assert "m1/progress.csv" in first and f"logs: {logs / 'm1'} " in out
    code, _, err = _train(capsys, "--out", str(tmp_path / "m2.zip"), "--log-dir", str(logs), "--seed", "1")
    assert code == 0, err
    code, _, err = _train(capsys, "--out", str(tmp_path / "m1.zip"), "--log-dir", str(logs), "--seed", "2", "--force")
    assert code == 0, err
    after = _files(logs)
    assert {k: after[k] for k in first} == first  # every file of the first run, unchanged
    assert sorted(p.name for p in logs.iterdir()) == ["m1", "m1-2", "m2"]
    for run, model in (("m2", "m2"), ("m1-2", "m1")):
        assert (logs / run / "progress.csv").read_text().startswith("step,")
        assert json.loads((tmp_path / f"{model}.json").read_text())["log_dir"] == str(logs / run)


def test_a_log_dir_that_is_a_symbolic_link_is_refused_before_any_work(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    target = tmp_path / "target"
    target.mkdir()
    (tmp_path / "link").symlink_to(target, target_is_directory=True)
    code, out, err = _train(capsys, "--out", str(tmp_path / "m.zip"), "--log-dir", str(tmp_path / "link"))
    assert code == 2 and out == "" and err.count("\n") == 1 and err.startswith("error: --log-dir"), err
    assert "symbolic link" in err
    assert list(target.iterdir()) == [] and not (tmp_path / "m.zip").exists()


@pytest.mark.parametrize("where", ["the folder", "a folder above it"])
def test_a_log_dir_that_is_a_file_is_one_error_line(tmp_path: Path, capsys: pytest.CaptureFixture[str], where: str) -> None:
    """It was a traceback (``FileExistsError``, exit 1); the user's file is kept."""
    mine = tmp_path / "notes.txt"
    mine.write_text("the user's notes")
    log_dir = mine if where == "the folder" else mine / "logs"
    code, out, err = _train(capsys, "--out", str(tmp_path / "m.zip"), "--log-dir", str(log_dir))
    assert code == 2 and out == "" and err.count("\n") == 1 and err.startswith("error: --log-dir"), err
    assert "is a file, not a folder" in err and "Traceback" not in err
    assert mine.read_text() == "the user's notes" and not (tmp_path / "m.zip").exists()


def test_run_folders_are_new_and_a_run_that_logged_nothing_leaves_none(tmp_path: Path) -> None:
    logs = tmp_path / "logs"
    (logs / "m").mkdir(parents=True)
    (logs / "m-2").symlink_to(tmp_path, target_is_directory=True)  # a name taken by a link is skipped, not followed
    assert new_run_folder(logs, "m") == logs / "m-3"
    with pytest.raises(KeyboardInterrupt), run_log_folder(logs, "m") as run:
        assert run == logs / "m-4" and run.is_dir()
        (run / "events.out.tfevents.1").write_bytes(b"")
        raise KeyboardInterrupt
    assert not (logs / "m-4").exists()
    with pytest.raises(KeyboardInterrupt), run_log_folder(logs, "m") as run:
        (run / "progress.csv").write_text("step,x\n1,2\n")  # a row logged: the run's logs are kept, whole
        raise KeyboardInterrupt
    assert (logs / "m-4" / "progress.csv").read_text() == "step,x\n1,2\n"
    with pytest.raises(ProblemError, match="symbolic link"):
        new_run_folder(logs / "m-2", "m")


def test_the_trainers_logs_refuse_a_link_a_file_and_an_earlier_runs_csv(tmp_path: Path) -> None:
    """``agents.native_ppo.train(args, log_dir=...)`` from Python keeps the same rules."""
    from agents.native.logs import Logs

    (tmp_path / "file").write_text("mine")
    (tmp_path / "link").symlink_to(tmp_path / "elsewhere", target_is_directory=True)
    (tmp_path / "old").mkdir()
    (tmp_path / "old" / "progress.csv").write_text("step\n1\n")
    for name, says in (("file", "is a file"), ("link", "symbolic link"), ("old", "earlier run")):
        with pytest.raises(ValueError, match=says):
            Logs(tmp_path / name, quiet=True)
    assert (tmp_path / "file").read_text() == "mine" and not (tmp_path / "elsewhere").exists()
    assert (tmp_path / "old" / "progress.csv").read_text() == "step\n1\n"
