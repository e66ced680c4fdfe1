"""Output files and standard output of every command.

Output files are checked before any expensive work (:func:`check_output_path`,
:func:`prepare_output_folder`) and written through a temporary file
(:func:`write_atomically`), so nothing a user made is overwritten without ``--force`` and
an interrupted run leaves no truncated file. Standard output holds a command's result
only; with ``--json`` exactly one JSON document (:func:`json_safe`, :func:`print_json`).
"""

from __future__ import annotations

import json
import math
import os
import sys
import tempfile
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from synthesis.model.errors import ProblemError


def _nearest_existing(path: Path) -> Path:
    """``path`` or its closest ancestor that exists (``.`` for a relative path with none)."""
    p = path
    while not p.exists() and not p.is_symlink():
        if p.parent == p:
            break
        p = p.parent
    return p


def _probe_folder(folder: Path, what: str, path: Path) -> None:
    """Raise ProblemError unless a file can be created in ``folder`` (tried, then removed).

    Permission bits lie to root and on read-only mounts; creating a file does not.
    """
    try:
        fd, name = tempfile.mkstemp(prefix=".flowtest-probe-", dir=folder)
    except OSError as exc:
        raise ProblemError(f"cannot write the {what} {str(path)!r}: {str(folder)!r}: {exc.strerror or exc}") from None
    os.close(fd)
    os.unlink(name)


def check_output_path(path: Path, force: bool, what: str) -> None:
    """Check an output file before any expensive work (raises ProblemError).

    Refused: a folder; a symbolic link (never replaced, even with ``--force``); an
    existing file without ``--force``; a path under a file; a place where nothing can
    be written. Nothing is created.
    """
    if path.is_symlink():
        raise ProblemError(f"{what} {str(path)!r} is a symbolic link; FlowTest never replaces one")
    if path.is_dir():
        raise ProblemError(f"{what} {str(path)!r} is a directory, not a file")
    if path.exists() and not force:
        raise ProblemError(f"{what} {str(path)!r} exists; use --force to overwrite")
    if path.exists() and not path.is_file():
        raise ProblemError(f"{what} {str(path)!r} is not a regular file")
    base = _nearest_existing(path.parent)
    if not base.exists():  # a relative path whose every part is missing: the working folder
        base = Path(".")
    if not base.is_dir():
        raise ProblemError(f"{what} {str(path)!r}: {str(base)!r} is a file, not a folder")
    _probe_folder(base, what, path)


def prepare_output_folder(folder: Path, marker: str, force: bool, what: str, hint: str = "use --force") -> None:
    """Create or accept an output folder FlowTest may write into (raises ProblemError).

    A folder that already holds files FlowTest did not write (no ``marker`` file from an
    earlier run) is refused unless ``force``; a file in its place, or a folder nothing can
    be written into, is refused always. On success the folder exists and holds ``marker``.
    """
    if folder.exists() and not folder.is_dir():
        raise ProblemError(f"{what} {str(folder)!r} exists and is not a folder")
    if folder.is_dir():
        try:
            foreign = any(folder.iterdir()) and not (folder / marker).exists()
        except OSError as exc:
            raise ProblemError(f"cannot read the {what} {str(folder)!r}: {exc.strerror or exc}") from None
        if foreign and not force:
            raise ProblemError(
                f"{what} {str(folder)!r} already holds files FlowTest did not write; {hint} or choose another folder"
            )
    else:
        base = _nearest_existing(folder.parent)
        if base.exists() and not base.is_dir():
            raise ProblemError(f"{what} {str(folder)!r}: {str(base)!r} is a file, not a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ProblemError(f"cannot create the {what} {str(folder)!r}: {exc.strerror or exc}") from None
    _probe_folder(folder, what, folder)
    mark = folder / marker
    if mark.is_symlink():
        raise ProblemError(f"{str(mark)!r} is a symbolic link; FlowTest never replaces one")
    if not mark.exists():
        write_atomically(mark, lambda tmp: tmp.write_text(f"written by FlowTest ({what}); its files may be overwritten by the next run\n"))


def write_atomically(path: Path, write: Callable[[Path], object]) -> None:
    """Create ``path``'s parent directories and write it through a temporary file.

    ``write`` writes a given path; the result replaces ``path`` only once complete, so
    an interrupted run never leaves a truncated artifact or picture behind. A symbolic
    link at ``path`` is never replaced (ProblemError).
    """
    if path.is_symlink():
        raise ProblemError(f"{str(path)!r} is a symbolic link; FlowTest never replaces one")
    if path.is_dir():
        raise ProblemError(f"{str(path)!r} is a directory, not a file")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ProblemError(f"cannot create the directory of {str(path)!r}: {exc.strerror or exc}") from None
    # same directory (so the rename is atomic), same suffix (it picks the picture's format),
    # created by `write` itself so the file gets the user's usual permissions
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.{threading.get_ident()}.tmp{path.suffix}")
    try:
        write(tmp)
        os.replace(tmp, path)
    except OSError as exc:
        raise ProblemError(f"cannot write {str(path)!r}: {exc.strerror or exc}") from None
    finally:
        tmp.unlink(missing_ok=True)


def json_safe(value: Any) -> Any:
    """Plain JSON data: numpy scalars and arrays converted, non-finite floats as ``null``.

    ``json.dumps`` would otherwise fail on numpy integers or write ``Infinity``, which
    is not JSON.
    """
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist())
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, (float, np.floating)):
        v = float(value)
        return v if math.isfinite(v) else None
    return value


def print_json(document: Any) -> None:
    """Write ``document`` (plain JSON data, see :func:`json_safe`) as one line on standard
    output: what ``--json`` promises, the whole of stdout."""
    sys.stdout.write(json.dumps(document, allow_nan=False) + "\n")
    sys.stdout.flush()
