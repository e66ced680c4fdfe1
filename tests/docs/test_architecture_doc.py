"""docs/architecture.md stays true to the code: every file it names exists, its module map
names every module of the four packages, and its public-API list of ``synthesis`` is
``synthesis.__all__``.

A module added, moved or removed without its line in the map fails here, with the path.
"""

from __future__ import annotations

import fnmatch
import re
from pathlib import Path

import synthesis

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "architecture.md"
PACKAGES = ("synthesis", "flowtest_env", "agents", "experiments")
PATH = re.compile(r"\b((?:synthesis|flowtest_env|agents|experiments|tests)/[\w/*.-]*\.py)\b")


def _section(text: str, title: str) -> str:
    """The text of the ``## title`` section."""
    m = re.search(rf"^## {re.escape(title)}\n(.*?)(?=^## |\Z)", text, flags=re.M | re.S)
    assert m, f"docs/architecture.md has no '## {title}' section"
    return m.group(1)


def test_every_file_the_page_names_exists() -> None:
    text = DOC.read_text()
    missing = []
    for path in sorted(set(PATH.findall(text))):
        hits = [p for p in ROOT.glob(path)] if "*" in path else [ROOT / path] if (ROOT / path).exists() else []
        if not hits:
            missing.append(path)
    assert not missing, f"docs/architecture.md names files that do not exist: {missing}"


def test_the_module_map_names_every_module() -> None:
    """Each module of the four packages is on a line of "Module map" (a ``*`` pattern such
    as ``experiments/bench_*.py`` covers the files it matches); package ``__init__`` files
    count through their folder (``synthesis/routing/``)."""
    section = _section(DOC.read_text(), "Module map")
    named = set(PATH.findall(section))
    unnamed = []
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            if path.name == "__init__.py":
                folder = rel.rsplit("/", 1)[0] + "/"
                if folder not in section and rel not in named:
                    unnamed.append(folder)
            elif not any(rel == n or ("*" in n and fnmatch.fnmatch(rel, n)) for n in named):
                unnamed.append(rel)
    assert not unnamed, f"docs/architecture.md's module map does not name: {unnamed}"


def test_the_public_api_list_is_synthesis_all() -> None:
    """The names on the section's bullet lines are exactly ``synthesis.__all__``."""
    section = _section(DOC.read_text(), "The public API of synthesis")
    bullets = re.findall(r"^- (.*?)(?=^- |^\S|\Z)", section, flags=re.M | re.S)
    listed = {name for b in bullets for name in re.findall(r"`(\w+)`", b)}
    exported = set(synthesis.__all__)
    assert listed == exported, f"docs/architecture.md's public API of synthesis: missing {sorted(exported - listed)}, not exported {sorted(listed - exported)}"
