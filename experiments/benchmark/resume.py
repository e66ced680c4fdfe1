"""A benchmark that can be stopped and continued: its stored configuration and the records of
its finished training runs (``flowtest benchmark --resume``, docs/benchmark-protocol.md).

A benchmark folder holds ``benchmark-config.json`` (:data:`CONFIG_FILE`, written before any
work: the configuration, :func:`config_document`) and, for every training run that finished,
its model ``models/NAME.zip`` and then its record ``models/NAME.json`` (:func:`write_record`:
the run's steps, times and learning curve, the digest of the configuration it was trained
under and the model file's SHA-256). Both files are written whole (a temporary file renamed),
the record after the model, so a run stopped at any moment has either a record whose model is
exactly the file it names, or no record: :func:`read_record` takes a run as finished only
then. ``--resume`` continues the same configuration only (:func:`check_same_config`), keeps
the finished runs and trains the rest; the table is the same as an uninterrupted run's.

Example::

    from experiments.benchmark import benchmark

    benchmark("safety2/4x4", "bench", suts=("ppo",), steps=1024, seeds=(0, 1))   # stopped by Ctrl-C ...
    benchmark("safety2/4x4", "bench", suts=("ppo",), steps=1024, seeds=(0, 1), resume=True)  # ... continued
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
from pathlib import Path
from typing import Any

from experiments.outputs import json_safe, write_atomically
from synthesis.model.errors import ProblemError

from .config import BenchmarkConfig

CONFIG_FILE = "benchmark-config.json"
"""The configuration of the benchmark in a folder, written before any work."""

CONFIG_FORMAT = "flowtest-benchmark-config"
RECORD_FORMAT = "flowtest-benchmark-run"
FORMAT_VERSION = 1

NOT_COMPARED = ("workers",)
"""Settings that do not change the results (how many runs train at once), left out of the
stored configuration: a benchmark may be resumed with other values."""

_FLAGS = {"suts": "--sut", "algos": "--algo"}


def config_document(config: BenchmarkConfig) -> dict[str, Any]:
    """The settings of ``config`` that decide the results, as plain JSON data."""
    doc = {k: v for k, v in dataclasses.asdict(config).items() if k not in NOT_COMPARED}
    return dict(json.loads(json.dumps(json_safe(doc), allow_nan=False)))


def config_digest(config: BenchmarkConfig) -> str:
    """The SHA-256 of :func:`config_document` (keys sorted): what a run record was trained under."""
    text = json.dumps(config_document(config), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def write_config(out: Path, config: BenchmarkConfig, commit: str | None) -> None:
    """Write ``out/benchmark-config.json`` (whole or not at all)."""
    from .config import command_of

    doc = {"format": CONFIG_FORMAT, "version": FORMAT_VERSION, "config": config_document(config), "command": command_of(config, str(out)), "commit": commit}
    write_atomically(out / CONFIG_FILE, lambda tmp: tmp.write_text(json.dumps(doc, indent=1) + "\n"))


def stored_config(out: Path) -> dict[str, Any]:
    """The stored configuration document of the benchmark in ``out``.

    Raises
    ------
    ProblemError
        If there is none, or it cannot be read as one.
    """
    path = out / CONFIG_FILE
    if path.is_symlink() or not path.is_file():
        raise ProblemError(
            f"--resume: the benchmark folder {str(out)!r} holds no configuration ({CONFIG_FILE}) to resume; use --force to start over, or choose another folder"
        )
    try:
        doc = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise ProblemError(f"--resume: {str(path)!r} cannot be read: {exc}") from None
    if not isinstance(doc, dict) or doc.get("format") != CONFIG_FORMAT or not isinstance(doc.get("config"), dict):
        raise ProblemError(f"--resume: {str(path)!r} is not a benchmark configuration")
    return doc


def _shown(value: Any) -> str:
    if isinstance(value, list):
        return " ".join(map(str, value)) if value else "(none)"
    return str(value)


def check_same_config(out: Path, config: BenchmarkConfig) -> dict[str, Any]:
    """Refuse (ProblemError, one line) to resume the benchmark in ``out`` with a configuration
    other than its stored one, naming the settings that differ; the stored document otherwise."""
    doc = stored_config(out)
    stored, now = doc["config"], config_document(config)
    differ = [k for k in dict.fromkeys([*stored, *now]) if stored.get(k) != now.get(k)]
    if differ:
        shown = "; ".join(f"{_FLAGS.get(k, '--' + k.replace('_', '-'))} {_shown(stored.get(k))} there, {_shown(now.get(k))} here" for k in differ)
        raise ProblemError(
            f"--resume: the benchmark in {str(out)!r} was started with other settings ({shown}); "
            "give the same settings to continue it, or --force to start over"
        )
    return doc


def record_path(model: Path) -> Path:
    """The record of the run whose model is ``model`` (``models/NAME.json``)."""
    return model.with_suffix(".json")


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def write_record(model: Path, config: BenchmarkConfig, run: dict[str, Any]) -> None:
    """Record a finished training run: ``run`` (plain data: algo, seed, train tests, steps,
    times, curve) with the configuration's digest and the model file's SHA-256, written whole
    after the model."""
    doc = {"format": RECORD_FORMAT, "version": FORMAT_VERSION, "config": config_digest(config), "model": model.name, "sha256": _sha256(model), **run}
    write_atomically(record_path(model), lambda tmp: tmp.write_text(json.dumps(json_safe(doc)) + "\n"))


def read_record(model: Path, config: BenchmarkConfig) -> dict[str, Any] | None:
    """The record of a run that finished under ``config`` with the model at ``model``, or
    ``None``: no record, a record of another configuration or format, or a model that is not
    the file recorded (missing, replaced, a link)."""
    path = record_path(model)
    if path.is_symlink() or not path.is_file() or model.is_symlink() or not model.is_file():
        return None
    try:
        doc = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, ValueError):
        return None
    if (
        not isinstance(doc, dict)
        or doc.get("format") != RECORD_FORMAT
        or doc.get("version") != FORMAT_VERSION
        or doc.get("config") != config_digest(config)
        or doc.get("model") != model.name
    ):
        return None
    try:
        if doc.get("sha256") != _sha256(model):
            return None
    except OSError:
        return None
    return doc


def remove_temporaries(out: Path) -> int:
    """Remove the temporary files a stopped run of this benchmark left in ``out`` (the hidden
    ``.NAME.PID.TID.tmp...`` files of :func:`experiments.outputs.write_atomically`, left by a
    training process killed while it saved); the number removed. Links are never followed
    nor removed."""
    removed = 0
    for folder, _, files in os.walk(out):  # links to folders are not followed
        for name in files:
            p = Path(folder) / name
            if name.startswith(".") and ".tmp" in name and not p.is_symlink() and p.is_file():
                p.unlink(missing_ok=True)
                removed += 1
    return removed
