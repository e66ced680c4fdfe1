"""The training logs: ``progress.csv`` (always, rewritten atomically at every row) and
TensorBoard events (when the ``tensorboard`` package is there).

Example::

    from agents.native.logs import Logs
    logs = Logs("runs/a")
    logs.add(4096, {"loss/entropy": 1.3})
    logs.close()
"""

from __future__ import annotations

import csv
import io
import os
import sys
from pathlib import Path
from typing import Any


class Logs:
    """CSV always (``progress.csv``, rewritten atomically at every row), TensorBoard when
    the ``tensorboard`` package is there (a one-line note on stderr when not).

    The folder is checked first (ValueError): never a symbolic link, never a file, and never
    one that already holds an earlier run's ``progress.csv`` (choose a new folder per run;
    ``flowtest train --log-dir`` makes one inside the folder given)."""

    def __init__(self, log_dir: str | Path | None, quiet: bool = False) -> None:
        self.dir = Path(log_dir) if log_dir is not None else None
        self.rows: list[dict[str, Any]] = []
        self.writer: Any = None
        if self.dir is None:
            return
        if self.dir.is_symlink():
            raise ValueError(f"log folder {str(self.dir)!r} is a symbolic link; FlowTest never writes through one")
        if self.dir.exists() and not self.dir.is_dir():
            raise ValueError(f"log folder {str(self.dir)!r} is a file, not a folder")
        csv_path = self.dir / "progress.csv"
        if csv_path.exists() or csv_path.is_symlink():
            raise ValueError(f"log folder {str(self.dir)!r} already holds the progress.csv of an earlier run; choose a new folder")
        try:
            self.dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ValueError(f"cannot create the log folder {str(self.dir)!r}: {exc.strerror or exc}") from None
        try:
            from torch.utils.tensorboard import SummaryWriter
        except ImportError:
            if not quiet:
                sys.stderr.write("flowtest: TensorBoard logs need the tensorboard package (pip install 'flowtest[rl]'); writing progress.csv only\n")
            return
        self.writer = SummaryWriter(str(self.dir))

    def add(self, step: int, values: dict[str, float]) -> None:
        """One row: scalars at ``step``."""
        row = {"step": step, **{k: round(v, 6) if isinstance(v, float) else v for k, v in values.items()}}
        self.rows.append(row)
        if self.writer is not None:
            for k, v in values.items():
                self.writer.add_scalar(k, v, step)
        if self.dir is not None:
            self._write_csv()

    def _write_csv(self) -> None:
        assert self.dir is not None
        keys = list(dict.fromkeys(k for row in self.rows for k in row))
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=keys)
        w.writeheader()
        w.writerows(self.rows)
        path = self.dir / "progress.csv"
        tmp = path.with_name(f".progress.{os.getpid()}.tmp")
        try:
            tmp.write_text(buf.getvalue())
            os.replace(tmp, path)
        finally:
            tmp.unlink(missing_ok=True)

    def close(self, wait: bool = True) -> None:
        """Flush and close the TensorBoard writer. ``wait=False`` (a run ended by an
        exception, Ctrl-C above all): drop it without waiting for its thread. A
        KeyboardInterrupt raised inside the writer's queue can leave that thread unable
        to wake, and waiting for it would hang the interrupted command for good; the
        thread is a daemon, and ``progress.csv`` already holds every row."""
        writer, self.writer = self.writer, None
        if writer is not None and wait:
            writer.close()


__all__ = ["Logs"]
