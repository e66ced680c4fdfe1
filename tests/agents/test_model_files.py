"""Model files are data, not code: a stable-baselines3 zip (which loading unpickles) runs
nothing without the user's opt-in, on every command that loads a model; a native
checkpoint is read without unpickling and refuses anything but its JSON and plain arrays.

Each hostile file is made here: a pickle whose ``__reduce__`` makes a marker folder.
"""

from __future__ import annotations

import base64
import io
import json
import os
import pickle
import zipfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from agents.base import PolicyError
from agents.checkpoint import (
    CheckpointError,
    UntrustedModelError,
    load_checkpoint,
    save_checkpoint,
    trust_pickled_models,
)
from agents.ppo import load_model
from experiments.cli.cli import main


class Payload:
    """Unpickling it makes the folder ``path`` (what a hostile model file would do, harmlessly)."""

    def __init__(self, path: Path) -> None:
        self.path = str(path)

    def __reduce__(self) -> tuple[object, tuple[str]]:
        return (os.mkdir, (self.path,))


def evil_sb3_zip(path: Path, marker: Path) -> Path:
    """A stable-baselines3-shaped zip (a ``data`` JSON whose policy class is a serialized
    object, as SB3 writes it) carrying :class:`Payload`."""
    blob = base64.b64encode(pickle.dumps(Payload(marker))).decode()
    data = {
        "policy_class": {":type:": "<class 'abc.ABCMeta'>", ":serialized:": blob, "__module__": "sb3_contrib.common.maskable.policies"},
        "observation_space": {":type:": "<class 'gymnasium.spaces.box.Box'>", ":serialized:": blob},
    }
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("data", json.dumps(data))
        z.writestr("_stable_baselines3_version", "2.3.0")
        z.writestr("policy.pth", pickle.dumps(Payload(marker)))
    return path


@pytest.fixture(autouse=True)
def _untrusted() -> Iterator[None]:
    trust_pickled_models(False)
    yield
    trust_pickled_models(False)


def _run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    try:
        code = main(argv)
    except SystemExit as exc:
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize(
    "argv",
    [
        ["evaluate", "--env", "small-reactive", "--sut", "ppo:{evil}", "--episodes", "1", "--out", "{out}"],
        ["evaluate", "--env", "FlowTest-Maze2-v0", "--tester", "ppo:{evil}", "--sut", "random", "--episodes", "1", "--out", "{out}"],
        ["evaluate", "--env", "FlowTest-Maze2-v0", "--tester", "ppo:{folder}", "--sut", "random", "--episodes", "1", "--out", "{out}"],
        ["benchmark", "--pool", "safety2/4x4", "--train-count", "2", "--test-count", "2", "--sut", "ppo:{evil}", "--out", "{out}"],
    ],
)
def test_a_pickled_model_runs_nothing_without_the_opt_in(tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str]) -> None:
    marker = tmp_path / "payload-ran"
    evil = evil_sb3_zip(tmp_path / "evil.zip", marker)
    folder = tmp_path / "testers"
    folder.mkdir()
    evil_sb3_zip(folder / "maze2.zip", marker)  # ppo:DIR: one tester per problem
    out = tmp_path / "out"
    args = [a.format(evil=evil, folder=folder, out=out) for a in argv]
    code, stdout, err = _run(args, capsys)
    assert not marker.exists()  # nothing was unpickled
    assert code == 2, err
    assert err.count("\n") == 1 and err.startswith("error: ") and "--trust-model" in err, err
    assert "stable-baselines3" in err and "Traceback" not in err
    assert not (out / "report.html").exists()


def test_the_payload_is_real_and_runs_only_when_trusted(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The same file does run its payload once the user trusts it (so the test above can
    fail), with one warning line first."""
    pytest.importorskip("stable_baselines3")
    marker = tmp_path / "payload-ran"
    evil = evil_sb3_zip(tmp_path / "evil.zip", marker)
    with pytest.raises(UntrustedModelError):
        load_model(evil)
    assert not marker.exists()
    trust_pickled_models(True)
    with pytest.raises(PolicyError):  # the payload ran, then SB3 found no model in it
        load_model(evil)
    assert marker.exists()
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "warning: loading" in err and "--trust-model" in err


def _native(tmp_path: Path) -> Path:
    path = tmp_path / "policy.zip"
    save_checkpoint(path, {"algo": "ppo", "note": "tiny"}, {"w": np.arange(6, dtype=np.float32).reshape(2, 3)})
    return path


def test_native_checkpoint_round_trip(tmp_path: Path) -> None:
    ck = load_checkpoint(_native(tmp_path))
    assert ck.settings["format"] == "flowtest-policy" and ck.settings["version"] == 1 and ck.settings["note"] == "tiny"
    assert ck.settings["tensors"] == {"w": {"shape": [2, 3], "dtype": "float32"}}
    np.testing.assert_array_equal(ck.tensors["w"], np.arange(6, dtype=np.float32).reshape(2, 3))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["policy.zip"]  # no temporary file left


def _rewrite(path: Path, change: dict[str, bytes | None]) -> None:
    with zipfile.ZipFile(path) as z:
        members = {n: z.read(n) for n in z.namelist()}
    for name, data in change.items():
        if data is None:
            members.pop(name, None)
        else:
            members[name] = data
    with zipfile.ZipFile(path, "w") as z:
        for name, data in members.items():
            z.writestr(name, data)


def _object_npy(marker: Path) -> bytes:
    buf = io.BytesIO()
    np.save(buf, np.array([Payload(marker)], dtype=object), allow_pickle=True)
    return buf.getvalue()


@pytest.mark.parametrize(
    "case, says",
    [
        ("pickled tensor", "not a plain .npy"),
        ("extra member", "unexpected members"),
        ("missing tensor", "missing members"),
        ("wrong shape", "settings say"),
        ("other format", "does not name the format"),
        ("newer version", "format version"),
        ("not json", "not JSON"),
    ],
)
def test_native_checkpoint_refuses_anything_else(tmp_path: Path, case: str, says: str) -> None:
    path = _native(tmp_path)
    marker = tmp_path / "payload-ran"
    settings = json.loads(zipfile.ZipFile(path).read("flowtest-policy.json"))
    buf = io.BytesIO()
    np.save(buf, np.zeros((3, 2), dtype=np.float32))
    changes: dict[str, dict[str, bytes | None]] = {
        "pickled tensor": {"tensors/w.npy": _object_npy(marker)},
        "extra member": {"payload.pkl": pickle.dumps(Payload(marker))},
        "missing tensor": {"tensors/w.npy": None},
        "wrong shape": {"tensors/w.npy": buf.getvalue()},
        "other format": {"flowtest-policy.json": json.dumps({**settings, "format": "sb3"}).encode()},
        "newer version": {"flowtest-policy.json": json.dumps({**settings, "version": 99}).encode()},
        "not json": {"flowtest-policy.json": b"\x80\x04not json"},
    }
    _rewrite(path, changes[case])
    with pytest.raises(CheckpointError, match=says):
        load_checkpoint(path)
    assert not marker.exists()


def test_a_broken_native_checkpoint_is_one_error_line_as_a_sut(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("torch")
    from agents.native_ppo import make_agent, save_policy

    path = _native(tmp_path)  # valid format, but no network in it
    with pytest.raises(PolicyError, match="not a valid FlowTest policy checkpoint"):
        load_model(path)
    # a network's checkpoint (its settings are checked before any tensor is read) with a pickled tensor
    path = tmp_path / "net.zip"
    save_policy(path, make_agent(3, 2, [4]), {"algo": "ppo", "network": {"kind": "mlp", "hidden": [4], "gru_hidden": 1}, "obs_size": 3, "n_actions": 2})
    load_model(path)
    _rewrite(path, {"tensors/actor.0.weight.npy": _object_npy(tmp_path / "m")})
    with pytest.raises(PolicyError, match="not a plain .npy"):
        load_model(path)
    assert not (tmp_path / "m").exists()


def test_the_demo_refuses_a_pickled_model_it_did_not_make(tmp_path: Path) -> None:
    from experiments.demo import check_demo_model

    folder = tmp_path / "evaluation"
    folder.mkdir()
    check_demo_model(folder)  # nothing there: the demo trains its own
    _native(tmp_path).rename(folder / "ppo-maze2.zip")
    check_demo_model(folder)  # a native checkpoint is data
    marker = tmp_path / "payload-ran"
    evil_sb3_zip(folder / "ppo-maze2.zip", marker)
    with pytest.raises(UntrustedModelError, match="--trust-model"):
        check_demo_model(folder)
    trust_pickled_models(True)
    check_demo_model(folder)  # trusted: the demo would load it
    assert not marker.exists()
