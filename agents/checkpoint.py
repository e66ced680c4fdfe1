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
  (little-endian ``float32``, C order, the plain header ``numpy.save`` writes).

Loading (:func:`load_checkpoint`) never unpickles and never evaluates: nothing in the
file is executed, so a native checkpoint is safe to load from anyone. And it checks
before it allocates: the settings JSON (at most 1 MiB, no ``NaN`` or ``Infinity``, any
nesting refused as one error), the declared tensors (plain names, whole-number shapes,
``float32``) against the budget :data:`MAX_TENSOR_BYTES`, the caller's check of the
settings (the native loader's: every field it uses, and the network they describe against
the declared tensors and the budget, :func:`agents.native.checkpoint.check_settings`),
then each ``.npy`` header (matched as text) against its declared shape and its member's
size; only then is each tensor's data read, into one array of its declared size. Every
refusal is one :class:`CheckpointError` line naming the file and the field.

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
import math
import os
import re
import struct
import sys
import zipfile
from collections.abc import Callable, Mapping
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
"""The budget: the largest total size of the tensors a checkpoint may declare, checked
before any of them is read (a FlowTest policy is a few megabytes)."""

MAX_NPY_HEADER_BYTES = 4096
"""Largest ``.npy`` header read (numpy writes about 128 bytes for a tensor)."""

FLOAT32 = np.dtype("<f4")
"""The one dtype of the tensors: little-endian ``float32`` (``.npy`` descr ``'<f4'``)."""

MAX_DIM = 1 << 31
"""A tensor dimension is below this."""

_NPY_HEADER = re.compile(
    r"\{'descr': '(?P<descr>[^']{0,16})', 'fortran_order': (?P<fortran>False|True), "
    r"'shape': \((?P<shape>(?:[0-9]{1,19}, )*(?:[0-9]{1,19},?)?)\), \} *\n"
)
"""The header numpy writes for a plain array (its dict's keys in order, then spaces and a
newline): the only one read. Nothing of it is evaluated."""

_TRUST = {"pickled": False}
_OWN: set[str] = set()


class UntrustedModelError(ProblemError):
    """A model file that would run code when loaded (a pickled stable-baselines3 zip),
    without the user's opt-in. Invalid input: the CLI prints one ``error:`` line, exit 2."""


class CheckpointError(ValueError):
    """A file that is not a valid native checkpoint. The message names the file (when
    it was read from one) and the field at fault: a setting (``settings field
    'network.hidden'``), a member (``tensors/actor.0.weight.npy``) or the settings member
    itself; ``field`` holds that name alone (``""`` when unknown)."""

    def __init__(self, message: str, field: str = "") -> None:
        super().__init__(message)
        self.field = field


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
    sys.stderr.write(
        f"flowtest: warning: loading {str(path)!r} unpickles it (a stable-baselines3 model runs code stored in the file); trusted with --trust-model\n"
    )
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
    arrays = {name: np.asarray(t, dtype=FLOAT32) for name, t in tensors.items()}
    for name in arrays:
        if not _plain_name(name):
            raise CheckpointError(f"tensor name {name!r} is not plain (letters, digits, '_' and '.')")
    doc = {**dict(settings), "format": FORMAT, "version": VERSION, "tensors": {n: {"shape": list(a.shape), "dtype": "float32"} for n, a in arrays.items()}}
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


def _plain_name(name: str) -> bool:
    return bool(name) and len(name) <= 200 and all(ch.isalnum() or ch in "_." for ch in name)


def _refuse_constant(name: str) -> Any:
    raise ValueError(f"the number {name} is not JSON")


def _read_settings(z: zipfile.ZipFile, info: zipfile.ZipInfo) -> dict[str, Any]:
    """The settings member as plain JSON data (no ``NaN`` or ``Infinity``, any depth
    Python's parser takes), naming the member in any refusal."""
    try:
        doc = json.loads(_read_member(z, info, MAX_SETTINGS_BYTES).decode("utf-8"), parse_constant=_refuse_constant)
    except RecursionError:
        raise CheckpointError(f"{SETTINGS_NAME} is not JSON FlowTest reads: nested too deeply", SETTINGS_NAME) from None
    except (UnicodeDecodeError, ValueError) as exc:
        raise CheckpointError(f"{SETTINGS_NAME} is not JSON ({exc})", SETTINGS_NAME) from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise CheckpointError(f"{SETTINGS_NAME} does not name the format {FORMAT!r}", "format")
    version = doc.get("version")
    if type(version) is not int or not 1 <= version <= VERSION:
        raise CheckpointError(f"settings field 'version': checkpoint format version {version!r}; this FlowTest reads 1..{VERSION}", "version")
    return doc


def declared_tensors(settings: Mapping[str, Any], budget: int = MAX_TENSOR_BYTES) -> dict[str, tuple[int, ...]]:
    """The tensors the settings declare (``tensors``: name -> ``shape``, ``dtype``), each
    name plain, each shape a list of whole numbers, each dtype ``float32``, together at
    most ``budget`` bytes: checked on the settings alone, before anything is read.

    Raises
    ------
    CheckpointError
        Naming the field at fault.
    """
    declared = settings.get("tensors")
    if not isinstance(declared, dict):
        raise CheckpointError("settings field 'tensors': the settings list no tensors (an object of name -> shape, dtype)", "tensors")
    shapes: dict[str, tuple[int, ...]] = {}
    total = 0
    for name, spec in declared.items():
        field = f"tensors.{name}"
        if not _plain_name(name):
            raise CheckpointError(f"settings field 'tensors': tensor name {name!r} is not plain (letters, digits, '_' and '.')", "tensors")
        shape = spec.get("shape") if isinstance(spec, dict) else None
        if not isinstance(shape, list) or len(shape) > 8 or not all(type(d) is int and 0 <= d < MAX_DIM for d in shape):
            raise CheckpointError(f"settings field '{field}': tensor {name!r}: bad shape {shape!r} in the settings", field)
        if spec.get("dtype") != "float32":
            raise CheckpointError(f"settings field '{field}': tensor {name!r} is {spec.get('dtype')!r}, not float32", field)
        shapes[name] = tuple(shape)
        total += FLOAT32.itemsize * math.prod(shape)
    if total > budget:
        raise CheckpointError(f"settings field 'tensors': the tensors declare {total:,} bytes, more than the budget of {budget:,}", "tensors")
    return shapes


def _read_npy_header(f: Any, member: str) -> tuple[tuple[int, ...], int]:
    """The shape of a plain little-endian ``float32`` ``.npy`` file and its header's length,
    read from its first bytes (the header matched as text, never evaluated)."""
    start = f.read(10)
    if len(start) != 10 or start[:6] != b"\x93NUMPY" or start[6] not in (1, 2, 3):
        raise CheckpointError(f"{member}: not a plain .npy array (no .npy magic and version)", member)
    if start[6] == 1:
        (length,), used = struct.unpack("<H", start[8:10]), 10
    else:
        more = f.read(2)
        (length,), used = struct.unpack("<I", start[8:10] + more), 12
    if length > MAX_NPY_HEADER_BYTES:
        raise CheckpointError(f"{member}: not a plain .npy array (a header of {length:,} bytes, more than {MAX_NPY_HEADER_BYTES})", member)
    raw = f.read(length)
    m = _NPY_HEADER.fullmatch(raw.decode("latin1")) if len(raw) == length else None
    if m is None:
        raise CheckpointError(f"{member}: not a plain .npy array (its header is not the plain header numpy writes)", member)
    if m["descr"] != FLOAT32.str or m["fortran"] != "False":
        raise CheckpointError(f"{member}: not a plain .npy array of float32 (dtype {m['descr']!r}, fortran_order {m['fortran']})", member)
    return tuple(int(d) for d in m["shape"].replace(",", " ").split()), used + length


def _read_tensor(z: zipfile.ZipFile, info: zipfile.ZipInfo, name: str, shape: tuple[int, ...]) -> np.ndarray:
    """The tensor of a member, its header checked against the settings' ``shape`` and the
    member's size before a byte of data is read; then read into one array of that size."""
    member = info.filename
    nbytes = FLOAT32.itemsize * math.prod(shape)
    with z.open(info) as f:
        header_shape, header_bytes = _read_npy_header(f, member)
        if header_shape != shape:
            raise CheckpointError(f"{member}: tensor {name!r} has the shape {list(header_shape)} in its header, settings say float32{list(shape)}", member)
        if info.file_size != header_bytes + nbytes:
            raise CheckpointError(f"{member}: tensor {name!r} has {info.file_size - header_bytes:,} bytes of data, its shape {list(shape)} {nbytes:,}", member)
        array = np.empty(shape, dtype=FLOAT32)
        raw = array.reshape(-1).view(np.uint8)  # the array's own bytes: filled in place, 1 MiB at a time
        done = 0
        while done < nbytes:
            chunk = f.read(min(1 << 20, nbytes - done))
            if not chunk:
                break
            raw[done : done + len(chunk)] = np.frombuffer(chunk, dtype=np.uint8)
            done += len(chunk)
        if done != nbytes or f.read(1):
            raise CheckpointError(f"{member}: tensor {name!r}: its data is not the {nbytes:,} bytes its header declares", member)
    return array


def load_checkpoint(path: str | Path, check: Callable[[dict[str, Any]], None] | None = None) -> Checkpoint:
    """Read a native checkpoint without unpickling anything (see the module docstring).

    Everything is checked before it is allocated: the settings JSON (bounded, no
    ``NaN``), the declared tensors against the budget (:data:`MAX_TENSOR_BYTES`), then
    ``check(settings)`` (the caller's own check of the settings, e.g. that they describe
    a network these tensors fit: :func:`agents.native.checkpoint.load_native`), then each
    ``.npy`` header against its declared shape and its member's size, and only then the
    data, each tensor read into one array of its declared size.

    Raises
    ------
    CheckpointError
        ``"'PATH' is not a valid FlowTest policy checkpoint: FIELD: what"`` if the file is
        not a zip, lacks or has extra members, its settings are not a native checkpoint of
        a version this FlowTest reads, ``check`` refuses them, or a tensor is not the
        ``float32`` array of the shape its settings declare.

    Examples
    --------
    >>> import tempfile, numpy as np
    >>> from pathlib import Path
    >>> from agents.checkpoint import load_checkpoint, save_checkpoint
    >>> path = Path(tempfile.mkdtemp()) / "policy.zip"
    >>> save_checkpoint(path, {"note": "tiny"}, {"w": np.ones((2, 3), dtype=np.float32)})
    >>> ck = load_checkpoint(path)
    >>> ck.settings["tensors"], ck.tensors["w"].shape
    ({'w': {'dtype': 'float32', 'shape': [2, 3]}}, (2, 3))
    """
    try:
        return _load(path, check)
    except CheckpointError as exc:
        raise CheckpointError(f"{str(path)!r} is not a valid FlowTest policy checkpoint: {exc}", exc.field) from None


def _load(path: str | Path, check: Callable[[dict[str, Any]], None] | None) -> Checkpoint:
    try:
        z = zipfile.ZipFile(path)
    except (OSError, zipfile.BadZipFile, ValueError) as exc:
        raise CheckpointError(f"not a zip archive ({exc})") from None
    with z:
        infos = {i.filename: i for i in z.infolist()}
        if SETTINGS_NAME not in infos:
            raise CheckpointError(f"no {SETTINGS_NAME} in the archive: not a native FlowTest checkpoint", SETTINGS_NAME)
        doc = _read_settings(z, infos[SETTINGS_NAME])
        shapes = declared_tensors(doc)
        expected = {SETTINGS_NAME} | {f"{TENSOR_DIR}{name}.npy" for name in shapes}
        extra = sorted(set(infos) - expected)
        missing = sorted(expected - set(infos))
        if extra or missing:
            raise CheckpointError(f"unexpected members {extra} or missing members {missing}", "tensors")
        if check is not None:
            check(doc)
        tensors = {name: _read_tensor(z, infos[f"{TENSOR_DIR}{name}.npy"], name, shape) for name, shape in shapes.items()}
    return Checkpoint(doc, tensors)


__all__ = [
    "Checkpoint",
    "CheckpointError",
    "UntrustedModelError",
    "FORMAT",
    "VERSION",
    "MAX_DIM",
    "MAX_TENSOR_BYTES",
    "declared_tensors",
    "is_native_checkpoint",
    "load_checkpoint",
    "save_checkpoint",
    "trust_pickled_models",
    "pickled_models_trusted",
    "warn_pickled",
    "refuse_pickled",
    "mark_own_file",
    "is_own_file",
]
