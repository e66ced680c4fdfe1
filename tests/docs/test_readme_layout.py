"""The README's Layout section stays true to the tree (issue 40): every folder, module and file
it names exists where it says, and every sub-package of the four packages is named in it.

The section is one code block; each line is ``<indent><names>  <description>``, where the
indent (0, 2 or 4 spaces) places the names under the last folder one level up, and the names
(separated by ``, ``) are folders (``routing/``), files (``pipeline.py``) or modules written
without ``.py`` (``demo``). Lines indented further continue a description.
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("synthesis", "flowtest_env", "agents", "experiments")
LEVELS = {0: 0, 2: 1, 4: 2}
"""Indent (spaces) -> depth of the names on that line."""


def layout_block() -> list[str]:
    """The lines of the code block under ``## Layout``."""
    text = (ROOT / "README.md").read_text()
    m = re.search(r"^## Layout\n+```\n(.*?)^```", text, flags=re.M | re.S)
    assert m, "README.md has no '## Layout' section with a code block"
    return m.group(1).splitlines()


def named_paths() -> list[tuple[int, Path]]:
    """``(line number, path)`` for every name of the block, relative to the repository root."""
    parents: list[Path] = [Path(".")]
    out: list[tuple[int, Path]] = []
    for number, line in enumerate(layout_block(), start=1):
        indent = len(line) - len(line.lstrip(" "))
        if not line.strip() or indent not in LEVELS:
            continue
        depth = LEVELS[indent]
        column = re.split(r" {2,}", line.strip(), maxsplit=1)[0]
        parent = parents[depth]
        for name in column.split(", "):
            path = parent / name.rstrip("/")
            out.append((number, path))
            if name.endswith("/"):
                del parents[depth + 1 :]
                parents.append(path)
    return out


def _exists(path: Path) -> bool:
    full = ROOT / path
    return full.exists() or (full.suffix != ".py" and full.with_suffix(".py").exists())


def test_every_name_in_the_layout_exists() -> None:
    missing = [f"line {n}: {p}" for n, p in named_paths() if not _exists(p)]
    assert not missing, f"README.md's Layout names what the tree does not have: {missing}"


def test_every_sub_package_is_in_the_layout() -> None:
    named = {p.as_posix() for _, p in named_paths()}
    packages = set(PACKAGES)
    for pkg in PACKAGES:
        packages |= {init.parent.relative_to(ROOT).as_posix() for init in (ROOT / pkg).rglob("__init__.py")}
    # a package's own sub-packages below the second level are described by its docstring, not the README
    expected = {p for p in packages if p.count("/") <= 2}
    assert sorted(expected - named) == [], "README.md's Layout does not name these packages"


def test_the_parser_reads_nesting() -> None:
    """The check reads the block's nesting (so it can fail): a nested folder is under its parent."""
    paths = {p.as_posix() for _, p in named_paths()}
    assert {"synthesis/routing/caps", "experiments/cli", "tests"} <= paths
