"""What a lab script does with its finished table: print it, and write it to ``--out`` when given."""

from __future__ import annotations

from pathlib import Path


def publish(text: str, out: str | Path | None) -> None:
    """Print ``text`` and, with ``out``, write it there as well (the file a benchmark page quotes)."""
    print(text)
    if out:
        Path(out).write_text(text)
