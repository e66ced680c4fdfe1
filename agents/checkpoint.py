"""Model files that are data, not code: the native policy checkpoint, and the trust gate
for stable-baselines3 zips.

**The native checkpoint** (written by :mod:`agents.native.checkpoint`, read here) is a zip
archive holding exactly:

* ``flowtest-policy.json``: plain settings (UTF-8 JSON, at most :data:`MAX_SETTINGS_BYTES`):
  ``format`` (:data:`FORMAT`), ``version`` (:data:`VERSION`), ``algo`` (``"ppo"`` or
  ``"recurrent-ppo"``), ``network`` (``kind`` ``"mlp"`` or ``"gru"``, ``hidden`` layer
  widths, ``gru_hidden`` width), ``obs`` (``obs_kind``, ``pad_to``, ``size``: the env's
  observation length), ``memory`` (``"none"`` or ``"visited"``), ``obs_size`` (the
  network's input length, memory included), ``n_actions``, ``env`` (what it trained on),
  ``training`` (every training argument), ``versions`` (FlowTest, torch, NumPy) and
  ``tensors`` (each tensor's name, ``shape`` and ``dtype``);
* ``tensors/<name>.npy``: one NumPy ``.npy`` file per tensor named in ``tensors``
  (``float32``, C order), read with ``numpy.load(allow_pickle=False)``.

Loading (:func:`load_checkpoint`) never unpickles: it reads the JSON, checks every
member name, size, dtype and shape against the settings, refuses anything else, and
returns arrays. Nothing in the file is executed. So a native checkpoint is safe to load
from anyone.

**stable-baselines3 zips are code.** SB3's ``load`` unpickles parts of the zip, and an
unpickled object can run any code it likes. FlowTest loads one only when the user says
they trust it: ``--trust-model`` on every command that loads a model, or, from Python::

    from agents.checkpoint import trust_pickled_models
    trust_pickled_models(True)   # for this process; False restores the default

Without it, loading an SB3 zip raises :class:`UntrustedModelError` (the CLI's one
``error:`` line, exit 2) before a byte of pickle is read; with it, one warning line goes
to stderr (:func:`warn_pickled`).
"""

from __future__ import annotations

import io
import json
import os
import sys
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from synthesis.model.errors import ProblemError

FORMAT = "flowtest-policy"
"""The ``format`` field of a native checkpoint's settings."""

VERSION = 1
"""The checkpoint format's version (a reader refuses a newer one)."""

SETTINGS_NAME = "flowtest-policy.json"
"""The settings member of the zip."""

TENSOR_DIR = "tensors/"
"""Where the tensors lie in the zip (``tensors/<name>.npy``)."""

MAX_SETTINGS_BYTES = 1 << 20
"""Largest settings JSON read."""

MAX_TENSOR_BYTES = 1 << 30
"""Largest total size of the tensors read (a FlowTest policy is a few megabytes)."""

_TRUST = {"pickled": False}
_OWN: set[str] = set()


class UntrustedModelError(ProblemError):
    """A model file that would run code when loaded (a pickled stable-baselines3 zip),
    without the user's opt-in. Invalid input: the CLI prints one ``error:`` line, exit 2."""


class CheckpointError(ValueError):
    """A file that is not a valid native checkpoint (the message says what is wrong)."""


def trust_pickled_models(trust: bool = True) -> None:
    """Allow (or, with ``False``, forbid again) loading stable-baselines3 zips, which
    unpickles them: only for files you made or trust like code. What ``--trust-model``
    sets for its command.

    Examples
    --------
    >>> from agents.checkpoint import pickled_models_trusted, trust_pickled_models
    >>> trust_pickled_models(True)      # this process may now load SB3 zips (one warning line each)
    >>> pickled_models_trusted()
    True
    >>> trust_pickled_models(False)     # refused again
    >>> pickled_models_trusted()
    False
    """
    _TRUST["pickled"] = bool(trust)


def pickled_models_trusted() -> bool:
    """Whether :func:`trust_pickled_models` is on in this process."""
    return _TRUST["pickled"]


def mark_own_file(path: str | Path) -> None:
    """Record that this process wrote the model at ``path`` itself (``flowtest train
    --trainer sb3`` evaluating what it just saved): loading it needs no opt-in."""
    _OWN.add(str(Path(path).resolve()))


def is_own_file(path: str | Path) -> bool:
    """Whether :func:`mark_own_file` recorded ``path`` in this process."""
    return str(Path(path).resolve()) in _OWN


def warn_pickled(path: str | Path) -> None:
    """The one warning line printed when a trusted SB3 zip is loaded."""
    sys.stderr.write(f"flowtest: warning: loading {str(path)!r} unpickles it (a stable-baselines3 model runs code "
                     "stored in the file); trusted with --trust-model\n")
    sys.stderr.flush()


def refuse_pickled(path: str | Path) -> UntrustedModelError:
    """The error for an SB3 zip loaded without trust (raise it)."""
    return UntrustedModelError(
        f"{str(path)!r} is a stable-baselines3 model: loading it unpickles code stored in the file; pass "
        "--trust-model if you trust it like a program (or retrain it with the native trainer, whose files are data)"
    )


def is_native_checkpoint(path: str | Path) -> bool:
    """Whether ``path`` is a zip whose settings member says it is a native checkpoint
    (reads the zip's directory only; :func:`load_checkpoint` checks the rest)."""
    try:
        with zipfile.ZipFile(path) as z:
            return SETTINGS_NAME in z.namelist()
    except (OSError, zipfile.BadZipFile, ValueError):
        return False


@dataclass
class Checkpoint:
    """A native checkpoint in memory: plain ``settings`` and named ``float32`` ``tensors``."""

    settings: dict[str, Any]
    tensors: dict[str, np.ndarray]


def _npy_bytes(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, np.ascontiguousarray(array), allow_pickle=False)
    return buf.getvalue()


def save_checkpoint(path: str | Path, settings: Mapping[str, Any], tensors: Mapping[str, np.ndarray]) -> None:
    """Write a native checkpoint to ``path`` atomically (a temporary file in the same
    folder, renamed when complete: an interrupted save leaves the old file or none).

    ``settings`` must be plain JSON data; ``format``, ``version`` and ``tensors`` are
    filled in here.

    Raises
    ------
    CheckpointError
        For a tensor name outside ``[A-Za-z0-9_.]`` or settings that are not JSON.
    """
    p = Path(path)
    arrays = {name: np.asarray(t, dtype=np.float32) for name, t in tensors.items()}
    for name in arrays:
        if not name or not all(ch.isalnum() or ch in "_." for ch in name):
            raise CheckpointError(f"tensor name {name!r} is not plain (letters, digits, '_' and '.')")
    doc = {**dict(settings), "format": FORMAT, "version": VERSION,
           "tensors": {n: {"shape": list(a.shape), "dtype": "float32"} for n, a in arrays.items()}}
    try:
        text = json.dumps(doc, indent=1, sort_keys=True, allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise CheckpointError(f"the settings are not plain JSON: {exc}") from None
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(f".{p.name}.{os.getpid()}.tmp")
    try:
        with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as z:
            z.writestr(SETTINGS_NAME, text + "\n")
            for name, a in arrays.items():
                z.writestr(f"{TENSOR_DIR}{name}.npy", _npy_bytes(a))
        os.replace(tmp, p)
    finally:
        tmp.unlink(missing_ok=True)


def _read_member(z: zipfile.ZipFile, info: zipfile.ZipInfo, limit: int) -> bytes:
    if info.file_size > limit:
        raise CheckpointError(f"member {info.filename!r} declares {info.file_size} bytes, more than {limit}")
    with z.open(info) as f:
        data = f.read(limit + 1)
    if len(data) > limit:
        raise CheckpointError(f"member {info.filename!r} is larger than {limit} bytes")
    return data


def load_checkpoint(path: str | Path) -> Checkpoint:
    """Read a native checkpoint without unpickling anything (see the module docstring).

    Raises
    ------
    CheckpointError
        If the file is not a zip, lacks or has extra members, its settings are not a
        native checkpoint of a version this FlowTest reads, or a tensor is not the
        ``float32`` array of the shape its settings declare.
    """
    try:
        z = zipfile.ZipFile(path)
    except (OSError, zipfile.BadZipFile) as exc:
        raise CheckpointError(f"not a zip archive ({exc})") from None
    with z:
        infos = {i.filename: i for i in z.infolist()}
        if SETTINGS_NAME not in infos:
            raise CheckpointError(f"no {SETTINGS_NAME} in the archive: not a native FlowTest checkpoint")
        try:
            doc = json.loads(_read_member(z, infos[SETTINGS_NAME], MAX_SETTINGS_BYTES).decode("utf-8"))
        except (UnicodeDecodeError, ValueError) as exc:
            raise CheckpointError(f"{SETTINGS_NAME} is not JSON ({exc})") from None
        if not isinstance(doc, dict) or doc.get("format") != FORMAT:
            raise CheckpointError(f"{SETTINGS_NAME} does not name the format {FORMAT!r}")
        if not isinstance(doc.get("version"), int) or not 1 <= doc["version"] <= VERSION:
            raise CheckpointError(f"checkpoint format version {doc.get('version')!r}; this FlowTest reads 1..{VERSION}")
        declared = doc.get("tensors")
        if not isinstance(declared, dict):
            raise CheckpointError("the settings list no tensors")
        expected = {SETTINGS_NAME} | {f"{TENSOR_DIR}{name}.npy" for name in declared}
        extra = sorted(set(infos) - expected)
        missing = sorted(expected - set(infos))
        if extra or missing:
            raise CheckpointError(f"unexpected members {extra} or missing members {missing}")
        budget = MAX_TENSOR_BYTES
        tensors: dict[str, np.ndarray] = {}
        for name, spec in declared.items():
            shape = spec.get("shape") if isinstance(spec, dict) else None
            if not isinstance(shape, list) or not all(isinstance(d, int) and 0 <= d < 1 << 31 for d in shape):
                raise CheckpointError(f"tensor {name!r}: bad shape {shape!r} in the settings")
            data = _read_member(z, infos[f"{TENSOR_DIR}{name}.npy"], budget)
            budget -= len(data)
            try:
                array = np.load(io.BytesIO(data), allow_pickle=False)
            except (ValueError, OSError, EOFError) as exc:
                raise CheckpointError(f"tensor {name!r} is not a plain .npy array ({exc})") from None
            if array.dtype != np.float32 or list(array.shape) != shape:
                raise CheckpointError(f"tensor {name!r} is {array.dtype}{list(array.shape)}, settings say float32{shape}")
            tensors[name] = array
    return Checkpoint(doc, tensors)


__all__ = [
    "Checkpoint", "CheckpointError", "UntrustedModelError", "FORMAT", "VERSION", "is_native_checkpoint",
    "load_checkpoint", "save_checkpoint", "trust_pickled_models", "pickled_models_trusted", "warn_pickled",
    "refuse_pickled", "mark_own_file", "is_own_file",
]
