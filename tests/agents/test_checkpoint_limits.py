"""Native checkpoints are checked before anything is built (issue 43, item 5).

A checkpoint is data from anyone: its declared network sizes, tensor shapes and dtypes are
checked against the file and against a budget before any allocation, and every parse
failure (the ``.npy`` headers, the JSON, each setting) is one :class:`CheckpointError`
naming the file and the field, which the command line prints as one ``error:`` line
(exit 2) through ``flowtest evaluate --sut ppo:PATH`` and ``flowtest benchmark --sut
ppo:PATH``. Each hostile file is made here from a small trained checkpoint.
"""

from __future__ import annotations

import json
import re
import struct
import subprocess
import sys
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

torch = pytest.importorskip("torch")

from agents.checkpoint import CheckpointError, load_checkpoint  # noqa: E402
from agents.native_ppo import NativeArgs, load_native, make_agent, train  # noqa: E402
from experiments.cli.cli import main  # noqa: E402

SETTINGS = "flowtest-policy.json"
WEIGHT = "tensors/actor.0.weight.npy"  # [16, 84] in the small checkpoint below


@pytest.fixture(scope="module")
def good(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small trained MLP checkpoint of small-reactive (84 inputs, 16 hidden, 5 actions)."""
    path = tmp_path_factory.mktemp("good") / "good.zip"
    train(
        NativeArgs(env_id="FlowTest-SmallReactive-v0", total_steps=64, num_envs=8, num_steps=8, hidden=(16,), device="cpu", eval_every=0),
        out=path,
        progress_bar=False,
    )
    return path


def _members(path: Path) -> dict[str, bytes]:
    with zipfile.ZipFile(path) as z:
        return {n: z.read(n) for n in z.namelist()}


def _write(path: Path, members: dict[str, bytes]) -> Path:
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as z:
        for name, data in members.items():
            z.writestr(name, data)
    return path


def _npy(header: str, data: bytes = b"") -> bytes:
    """A ``.npy`` file (format 1.0) with this header text, padded as numpy pads it."""
    raw = header.encode("latin1")
    raw += b" " * (64 - (10 + len(raw) + 1) % 64) + b"\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(raw)) + raw + data


def _float_header(shape: str) -> str:
    return "{'descr': '<f4', 'fortran_order': False, 'shape': " + shape + ", }"


SETTINGS_CASES: dict[str, tuple[str, Any, str]] = {
    # case: (the settings field set, its value, what the error must match)
    "a network over the budget": ("network.hidden", [16384, 16384], "'network'.*budget"),  # 700 KB declaring 3.4 GB
    "100,000 layers": ("network.hidden", [1] * 100_000, "'network.hidden'"),
    "hidden not a list": ("network.hidden", "16", "'network.hidden'"),
    "a width of 0": ("network.hidden", [0], "'network.hidden'"),
    "a float width": ("network.hidden", [16.0], "'network.hidden'"),
    "network not an object": ("network", "mlp", "'network'"),
    "an unknown kind": ("network.kind", "transformer", "'network.kind'"),
    "obs_size a string": ("obs_size", "84", "'obs_size'"),
    "obs_size not what the file holds": ("obs_size", 85, "'obs_size'"),
    "n_actions true": ("n_actions", True, "'n_actions'"),
    "obs not an object": ("obs", "x", "'obs'"),
    "obs_kind unknown": ("obs.obs_kind", "grid", "'obs.obs_kind'"),
    "pad_to a string": ("obs.pad_to", "x", "'obs.pad_to'"),
    "pad_to negative": ("obs.pad_to", -1, "'obs.pad_to'"),
    "pad_to huge": ("obs.pad_to", 10**30, "'obs.pad_to'"),
    "memory unknown": ("memory", 5, "'memory'"),
    "position reversed": ("position", [66, 60], "'position'"),
    "position strings": ("position", ["a", "b"], "'position'"),
    "position past the observation": ("position", [60, 10**12], "'position'"),
    "position a float": ("position", [60.5, 66], "'position'"),
    "position not a pair": ("position", 60, "'position'"),
    "tensor dtype": ("tensors/actor.0.weight", {"shape": [16, 84], "dtype": "float64"}, "actor.0.weight.*float32"),
    "tensor shape of bools": ("tensors/actor.0.weight", {"shape": [True, 84], "dtype": "float32"}, "actor.0.weight.*shape"),
    "tensors over the budget": ("tensors/actor.0.weight", {"shape": [2**30, 2**10], "dtype": "float32"}, "budget"),
    "tensors not an object": ("tensors", ["actor.0.weight"], "'tensors'"),
    "version true": ("version", True, "version"),
}


def _edit_settings(good: Path, out: Path, edit: Callable[[str], str]) -> Path:
    members = _members(good)
    members[SETTINGS] = edit(members[SETTINGS].decode()).encode()
    return _write(out, members)


def _set(field: str, value: Any) -> Callable[[str], str]:
    """Set the settings field ``a.b`` (``tensors/NAME``: a tensor's entry, whose name holds dots)."""

    def edit(text: str) -> str:
        doc = json.loads(text)
        if field.startswith("tensors/"):
            doc["tensors"][field[len("tensors/") :]] = value
            return json.dumps(doc)
        *parents, last = field.split(".")
        s = doc
        for p in parents:
            s = s[p]
        s[last] = value
        return json.dumps(doc)

    return edit


def _set_number(field: str, value: str) -> Callable[[str], str]:
    """Set ``field`` to ``value`` written as is (``NaN``, ``Infinity``: not JSON)."""

    def edit(text: str) -> str:
        doc = json.loads(text)
        doc[field] = "@@"
        return json.dumps(doc).replace('"@@"', value)

    return edit


def _hostile(good: Path, out: Path, case: str) -> tuple[Path, str]:
    """The file of ``case`` (written to ``out``) and the pattern its error must match."""
    if case in SETTINGS_CASES:
        field, value, says = SETTINGS_CASES[case]
        return _edit_settings(good, out, _set(field, value)), says
    if case == "obs_size Infinity":
        return _edit_settings(good, out, _set_number("obs_size", "Infinity")), "Infinity"
    if case == "n_actions NaN":
        return _edit_settings(good, out, _set_number("n_actions", "NaN")), "NaN"
    if case == "100,000-deep JSON":
        return _edit_settings(good, out, lambda t: t.rstrip()[:-1] + ', "deep": ' + "[" * 100_000 + "]" * 100_000 + "}"), "nested"
    members = _members(good)
    if case == "a .npy header of shape (2**40,)":
        members[WEIGHT] = _npy(_float_header(f"({2**40},)"))
        return _write(out, members), f"{WEIGHT}.*shape"
    if case == "a .npy header that is not a literal":
        members[WEIGHT] = _npy(_float_header("(" + "-" * 3000 + "16, 84)"), bytes(16 * 84 * 4))
        return _write(out, members), WEIGHT
    if case == "a .npy header that calls code":
        members[WEIGHT] = _npy("{'descr': __import__('os').getcwd(), 'fortran_order': False, 'shape': (16, 84), }", bytes(16 * 84 * 4))
        return _write(out, members), WEIGHT
    if case == "a .npy file shorter than its header says":
        members[WEIGHT] = _npy(_float_header("(16, 84)"), bytes(16 * 84 * 4 - 4))
        return _write(out, members), WEIGHT
    if case == "a .npy file longer than its header says":
        members[WEIGHT] = _npy(_float_header("(16, 84)"), bytes(16 * 84 * 4 + 4))
        return _write(out, members), WEIGHT
    raise AssertionError(case)


TEXT_CASES = ["obs_size Infinity", "n_actions NaN", "100,000-deep JSON"]
NPY_CASES = [
    "a .npy header of shape (2**40,)",
    "a .npy header that is not a literal",
    "a .npy header that calls code",
    "a .npy file shorter than its header says",
    "a .npy file longer than its header says",
]
CASES = [*SETTINGS_CASES, *TEXT_CASES, *NPY_CASES]


def test_the_small_checkpoint_loads(good: Path) -> None:
    """The file every case starts from is valid (so each case fails for its own change)."""
    model = load_native(good)
    assert model.agent.obs_size == 84 and model.agent.n_actions == 5 and model.position == slice(60, 66)


@pytest.mark.parametrize("case", CASES)
def test_a_hostile_checkpoint_is_one_error_naming_the_file_and_the_field(good: Path, tmp_path: Path, case: str) -> None:
    path, says = _hostile(good, tmp_path / "hostile.zip", case)
    with pytest.raises(CheckpointError, match=says) as caught:
        load_native(path)
    message = str(caught.value)
    assert str(path) in message and "\n" not in message, message


@pytest.mark.parametrize("case", CASES)
def test_flowtest_evaluate_says_it_in_one_error_line(good: Path, tmp_path: Path, case: str, capsys: pytest.CaptureFixture[str]) -> None:
    path, says = _hostile(good, tmp_path / "hostile.zip", case)
    try:
        code = main(["evaluate", "--env", "small-reactive", "--sut", f"ppo:{path}", "--episodes", "1", "--out", str(tmp_path / "r"), "-q"])
    except SystemExit as exc:
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    assert code == 2, err
    assert err.count("\n") == 1 and err.startswith("error: ") and str(path) in err and "Traceback" not in err, err
    assert re.search(says, err), err


@pytest.mark.parametrize("case", ["a network over the budget", "a .npy header of shape (2**40,)", "pad_to a string"])
def test_flowtest_benchmark_says_it_in_one_error_line(good: Path, tmp_path: Path, case: str, capsys: pytest.CaptureFixture[str]) -> None:
    path, says = _hostile(good, tmp_path / "hostile.zip", case)
    try:
        code = main(
            ["benchmark", "--pool", "safety2/4x4", "--train-count", "2", "--test-count", "2", "--sut", f"ppo:{path}", "--out", str(tmp_path / "b"), "-q"]
        )
    except SystemExit as exc:
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    lines = [line for line in err.splitlines() if line.startswith("error:")]
    assert code == 2, err
    assert len(lines) == 1 and str(path) in lines[0] and "Traceback" not in err, err


PEAK = r"""
import json, resource, sys
import numpy, torch
from agents.checkpoint import CheckpointError
from agents.native.checkpoint import load_native

def vm_bytes():
    for line in open("/proc/self/status"):
        if line.startswith("VmSize:"):
            return int(line.split()[1]) * 1024

soft, hard = resource.getrlimit(resource.RLIMIT_AS)
resource.setrlimit(resource.RLIMIT_AS, (vm_bytes() + (768 << 20), hard))  # a safety net: the case may not take the machine down
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
for path in sys.argv[1:]:
    try:
        load_native(path)
        said = "loaded"
    except CheckpointError as exc:
        said = "CheckpointError: " + str(exc)
    except BaseException as exc:
        said = type(exc).__name__ + ": " + str(exc)[:300]
    grew = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - base
    print(json.dumps({"path": path, "said": said, "grew_kib": grew}), flush=True)
"""


def test_no_allocation_before_the_size_check(good: Path, tmp_path: Path) -> None:
    """The three files that made the loader allocate: a 3.4 GB network declared by a 700 KB
    file, a ``.npy`` header declaring 4 TiB, and a 900 MiB zero tensor (a 1 MiB member once
    compressed) where the settings declare ``[16, 84]``. Each is refused with the peak
    memory of the loading process grown by less than 64 MiB (its address space is capped
    at 768 MiB above what the imports took, so a case that does allocate fails here)."""
    network, _ = _hostile(good, tmp_path / "network.zip", "a network over the budget")
    header, _ = _hostile(good, tmp_path / "header.zip", "a .npy header of shape (2**40,)")
    zeros = tmp_path / "zeros.zip"
    n = (900 << 20) // 4
    with zipfile.ZipFile(zeros, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=1) as z:
        for name, data in _members(good).items():
            if name != WEIGHT:
                z.writestr(name, data)
        with z.open(WEIGHT, "w", force_zip64=True) as f:
            f.write(_npy(_float_header(f"({n},)")))
            chunk = bytes(8 << 20)
            for _ in range((n * 4) // len(chunk)):
                f.write(chunk)
    assert zeros.stat().st_size < 8 << 20 and network.stat().st_size < 1 << 20
    proc = subprocess.run([sys.executable, "-c", PEAK, str(network), str(header), str(zeros)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    rows = [json.loads(line) for line in proc.stdout.splitlines()]
    assert len(rows) == 3, proc.stdout
    for row in rows:
        assert row["said"].startswith("CheckpointError: ") and row["path"] in row["said"], row
        assert row["grew_kib"] < 64 << 10, row


def test_the_declared_network_shapes_are_the_built_ones() -> None:
    """The shapes the loader checks before building (``network_shapes``) are those the
    networks have, for both kinds and several depths."""
    from agents.native.networks import network_shapes

    for kind in ("mlp", "gru"):
        for hidden in ([], [7], [9, 5], [4, 3, 2]):
            if kind == "mlp" and not hidden:
                continue
            built = {k: tuple(v.shape) for k, v in make_agent(11, 5, hidden, kind, 6).state_dict().items()}
            assert network_shapes(kind, 11, 5, hidden, 6) == built, (kind, hidden)


def test_load_checkpoint_checks_settings_before_reading_a_tensor(good: Path, tmp_path: Path) -> None:
    """The format reader calls the caller's check of the settings before it reads any tensor."""
    seen: list[str] = []

    def check(settings: dict[str, Any]) -> None:
        seen.append(settings["format"])
        raise CheckpointError("settings field 'x': refused by the caller")

    path, _ = _hostile(good, tmp_path / "header.zip", "a .npy header of shape (2**40,)")
    with pytest.raises(CheckpointError, match="refused by the caller"):
        load_checkpoint(path, check=check)
    assert seen == ["flowtest-policy"]
