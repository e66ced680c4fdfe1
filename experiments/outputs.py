"""Output files and standard output of every command.

Output files are checked before any expensive work (:func:`check_output_path`,
:func:`prepare_output_folder`) and written through a temporary file
(:func:`write_atomically`), so nothing a user made is overwritten without ``--force`` and
an interrupted run leaves no truncated file.

Outputs never follow a link: an output file that is a symbolic link is never replaced,
and no folder inside an output folder (``OUT/traces``, ``OUT/models``, ``OUT/pool``...) is
ever a link FlowTest writes through. :func:`prepare_output_folder` records the folder it
accepted; :func:`write_atomically` and :func:`output_subfolder` then refuse a path under it
that passes through a symbolic link (:func:`check_no_link_below`), and create the folders
they need one at a time, checking each. The output folder itself is the user's choice (a
link the user named is followed). Standard output holds a command's result
only; with ``--json`` exactly one JSON document (:func:`json_safe`, :func:`print_json`).

Training logs (``--log-dir``) are outputs too: :func:`check_log_dir` checks the folder before
any work (never a symbolic link, never a file), and :func:`run_log_folder` gives each run a
new folder inside it, so no run's logs are ever written over another's.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import sys
import tempfile
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
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


_OUTPUT_ROOTS: set[str] = set()
"""The output folders accepted by :func:`prepare_output_folder` in this process (absolute,
not resolved: a link the user named stays the name they gave)."""


def _absolute(path: Path) -> Path:
    return Path(os.path.abspath(path))


def _root_of(path: Path) -> Path | None:
    """The deepest accepted output folder ``path`` lies under (strictly), if any."""
    ap = _absolute(path)
    best: Path | None = None
    for root in _OUTPUT_ROOTS:
        r = Path(root)
        if r in ap.parents and (best is None or len(r.parts) > len(best.parts)):
            best = r
    return best


def check_no_link_below(path: Path, root: Path | None = None) -> None:
    """Refuse (ProblemError) a ``path`` whose folders below its output folder ``root``
    (default: the accepted output folder it lies under, see :func:`prepare_output_folder`)
    include a symbolic link, or that is itself one: FlowTest never writes through a link
    inside an output folder. Nothing is created."""
    root = root if root is not None else _root_of(path)
    ap = _absolute(path)
    if root is None:
        return
    rp = _absolute(root)
    for part in [ap, *ap.parents]:
        if part == rp or rp not in part.parents:
            break
        if part.is_symlink():
            raise ProblemError(f"{str(part)!r} inside the output folder {str(rp)!r} is a symbolic link; FlowTest never writes through one")


def _make_folders(folder: Path) -> None:
    """Create ``folder`` and its missing parents one at a time, refusing any that is (or
    becomes) a link below an accepted output folder."""
    missing: list[Path] = []
    p = folder
    while not (p.exists() or p.is_symlink()):
        missing.append(p)
        if p.parent == p:
            break
        p = p.parent
    check_no_link_below(folder)
    for m in reversed(missing):
        try:
            m.mkdir(exist_ok=True)
        except OSError as exc:
            raise ProblemError(f"cannot create the directory {str(m)!r}: {exc.strerror or exc}") from None
    check_no_link_below(folder)
    if not folder.is_dir():
        raise ProblemError(f"{str(folder)!r} is not a folder")


def output_subfolder(root: Path, name: str) -> Path:
    """``root / name``, created if missing: a folder inside an output folder, never a link
    (ProblemError). Commands use it for ``OUT/traces``, ``OUT/models``, ``OUT/pool``..."""
    sub = root / name
    check_no_link_below(sub, root)
    _make_folders(sub)
    check_no_link_below(sub, root)
    return sub


def check_output_path(path: Path, force: bool, what: str) -> None:
    """Check an output file before any expensive work (raises ProblemError).

    Refused: a folder; a symbolic link (never replaced, even with ``--force``); an
    existing file without ``--force``; a path under a file; a place where nothing can
    be written. Nothing is created.
    """
    if path.is_symlink():
        raise ProblemError(f"{what} {str(path)!r} is a symbolic link; FlowTest never replaces one")
    check_no_link_below(path)
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
            raise ProblemError(f"{what} {str(folder)!r} already holds files FlowTest did not write; {hint} or choose another folder")
    else:
        base = _nearest_existing(folder.parent)
        if base.exists() and not base.is_dir():
            raise ProblemError(f"{what} {str(folder)!r}: {str(base)!r} is a file, not a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ProblemError(f"cannot create the {what} {str(folder)!r}: {exc.strerror or exc}") from None
    _probe_folder(folder, what, folder)
    _OUTPUT_ROOTS.add(str(_absolute(folder)))
    for sub in folder.iterdir():  # a link inside is refused now, before any work
        if sub.is_symlink():
            raise ProblemError(
                f"{str(sub)!r} inside the {what} {str(folder)!r} is a symbolic link; FlowTest never writes through one: remove it or choose another folder"
            )
    mark = folder / marker
    if mark.is_symlink():
        raise ProblemError(f"{str(mark)!r} is a symbolic link; FlowTest never replaces one")
    if not mark.exists():
        write_atomically(mark, lambda tmp: tmp.write_text(f"written by FlowTest ({what}); its files may be overwritten by the next run\n"))


def write_atomically(path: Path, write: Callable[[Path], object]) -> None:
    """Create ``path``'s parent directories and write it through a temporary file.

    ``write`` writes a given path; the result replaces ``path`` only once complete, so
    an interrupted run never leaves a truncated artifact or picture behind. A symbolic
    link at ``path`` is never replaced, nor a folder inside an output folder written
    through when it is a link (ProblemError).
    """
    if path.is_symlink():
        raise ProblemError(f"{str(path)!r} is a symbolic link; FlowTest never replaces one")
    check_no_link_below(path)
    if path.is_dir():
        raise ProblemError(f"{str(path)!r} is a directory, not a file")
    _make_folders(path.parent)
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


def check_log_dir(log_dir: Path) -> None:
    """Check a training run's ``--log-dir`` before any work (raises ProblemError): a folder,
    or a path where one can be created; never a symbolic link (FlowTest never writes
    through one), never a file, and writable. Nothing is created."""
    if log_dir.is_symlink():
        raise ProblemError(f"--log-dir {str(log_dir)!r} is a symbolic link; FlowTest never writes through one: give the folder itself")
    if log_dir.exists() and not log_dir.is_dir():
        raise ProblemError(f"--log-dir {str(log_dir)!r} is a file, not a folder")
    base = _nearest_existing(log_dir)
    if not base.exists():  # a relative path whose every part is missing: the working folder
        base = Path(".")
    if not base.is_dir():
        raise ProblemError(f"--log-dir {str(log_dir)!r}: {str(base)!r} is a file, not a folder")
    _probe_folder(base, "log folder", log_dir)


def new_run_folder(log_dir: Path, name: str) -> Path:
    """Create and return a new folder for one run's logs inside ``log_dir`` (created if
    missing): ``log_dir/name``, or ``name-2``, ``name-3``... when that is taken, so a run
    never writes into an earlier run's logs (TensorBoard shows each folder as a run).
    The folder is made by this call (a name already used by anything, a link included, is
    skipped), never a link (ProblemError on a bad ``log_dir``, see :func:`check_log_dir`)."""
    check_log_dir(log_dir)
    try:
        log_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ProblemError(f"cannot create the log folder {str(log_dir)!r}: {exc.strerror or exc}") from None
    check_log_dir(log_dir)
    k = 1
    while True:
        run = log_dir / (name if k == 1 else f"{name}-{k}")
        try:
            run.mkdir()  # atomic: two runs starting at once get two folders
        except FileExistsError:
            k += 1
            continue
        except OSError as exc:
            raise ProblemError(f"cannot create the log folder {str(run)!r}: {exc.strerror or exc}") from None
        return run


@contextmanager
def run_log_folder(log_dir: Path, name: str) -> Iterator[Path]:
    """A new folder for one run's logs (:func:`new_run_folder`) for the duration of the run.
    A run that ends by an exception (Ctrl-C included) before it logged a row leaves nothing
    behind; one that logged keeps its logs, each file whole (``progress.csv`` is rewritten
    atomically at every row)."""
    run = new_run_folder(log_dir, name)
    try:
        yield run
    except BaseException:
        if not (run / "progress.csv").exists():
            shutil.rmtree(run, ignore_errors=True)  # a folder this run made, holding only what it wrote
        raise


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
