"""The benchmark pages hold together: docs/benchmarks.md is the index of docs/benchmarks/*.md,
every relative link in them reaches an existing file and, for a Markdown page, an existing
heading, and every ``python -m experiments...`` command they quote names a module of the
repository (a retired script only on the history page, with the last commit that had it)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
INDEX = ROOT / "docs" / "benchmarks.md"
PAGES_DIR = ROOT / "docs" / "benchmarks"
#: The pages the index must list: one per subject, and the history.
SUBJECT_PAGES = ("solvers.md", "environments.md", "training.md", "pools.md", "history.md")
#: Scripts retired from the repository whose commands history.md still quotes, with the last
#: commit that had each; history.md must name that commit.
RETIRED_MODULES = {"experiments.bypass_bound": "23821e8"}
#: Retired routing backends: history.md's table of retired pieces gives the last commit of each.
RETIRED_BACKENDS = {"`cover`": "4c05383", "`scip`": "4c05383", "bypass bound": "23821e8"}

LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
MODULE = re.compile(r"python -m (experiments(?:\.\w+)+)")


def pages() -> list[Path]:
    return [INDEX, *sorted(PAGES_DIR.glob("*.md"))]


def outside_code(text: str) -> str:
    """The text with fenced code blocks blanked (their lines kept, so line numbers hold)."""
    out, fence = [], False
    for line in text.split("\n"):
        if line.startswith("```"):
            fence = not fence
            out.append("")
        else:
            out.append("" if fence else line)
    return "\n".join(out)


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def anchors(page: Path) -> set[str]:
    """Every anchor of ``page``: GitHub's for its headings (a repeated one gets -1, -2, ...) and
    the ``<a id="...">`` it sets by hand (the index keeps the old notebook's anchors that way)."""
    seen: dict[str, int] = {}
    text = outside_code(page.read_text())
    found = set(re.findall(r'<a id="([^"]+)"></a>', text))
    for line in text.split("\n"):
        m = re.match(r"#{1,6} (.+)", line)
        if m:
            base = slug(m.group(1))
            n = seen.get(base, 0)
            seen[base] = n + 1
            found.add(base if n == 0 else f"{base}-{n}")
    return found


def test_slug_matches_github() -> None:
    assert slug("CP-SAT's phase 1") == "cp-sats-phase-1"
    assert slug("Session 11 (issue 18): MILP-reactive on 5x5 reaction |AP| = 7") == ("session-11-issue-18-milp-reactive-on-5x5-reaction-ap--7")
    assert slug("Fitting `reachability1/5x5`'s train split") == "fitting-reachability15x5s-train-split"


def test_index_keeps_the_notebooks_section_anchors() -> None:
    """Every section of the old notebook (history.md's ## headings, less the history page's own)
    has its old anchor on docs/benchmarks.md, on a row that links the section in history.md."""
    index = INDEX.read_text()
    history = PAGES_DIR / "history.md"
    own = {"retired-backends-and-scripts"}
    for line in outside_code(history.read_text()).split("\n"):
        if line.startswith("## ") and slug(line[3:]) not in own:
            anchor = slug(line[3:])
            assert f'<a id="{anchor}"></a>[' in index and f"(benchmarks/history.md#{anchor})" in index, (
                f"docs/benchmarks.md has no row for the notebook section #{anchor}"
            )


def test_index_lists_every_page() -> None:
    text = INDEX.read_text()
    for name in SUBJECT_PAGES:
        assert f"(benchmarks/{name})" in text, f"docs/benchmarks.md does not link benchmarks/{name}"
        assert (PAGES_DIR / name).is_file(), f"docs/benchmarks/{name} is missing"
    listed = set(re.findall(r"\(benchmarks/([\w-]+\.md)[)#]", text))
    assert listed == {p.name for p in PAGES_DIR.glob("*.md")}, "a page is not in the index, or the index names a missing one"


@pytest.mark.parametrize("page", pages(), ids=lambda p: p.relative_to(ROOT).as_posix())
def test_relative_links_resolve(page: Path) -> None:
    broken = []
    for target in LINK.findall(outside_code(page.read_text())):
        if re.match(r"[a-z]+:", target):
            continue  # http(s), mailto: not checked here
        path, _, anchor = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        if not dest.exists():
            broken.append(f"{target}: no file {dest}")
        elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            broken.append(f"{target}: no heading with anchor #{anchor} in {dest.relative_to(ROOT)}")
    assert not broken, f"{page.relative_to(ROOT)}: " + "; ".join(broken)


def links_into_benchmarks() -> list[tuple[Path, str]]:
    """(page, target) for every link of the README or another docs page into the benchmark pages."""
    found = []
    for page in [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]:
        if page == INDEX or PAGES_DIR in page.parents:
            continue
        for target in LINK.findall(outside_code(page.read_text())):
            path = target.partition("#")[0]
            if path and not re.match(r"[a-z]+:", target):
                dest = (page.parent / path).resolve()
                if dest == INDEX or PAGES_DIR in dest.parents:
                    found.append((page, target))
    return found


def test_other_docs_link_to_existing_benchmark_headings() -> None:
    """The README's and the other docs pages' links into the benchmark pages reach a file and a
    heading (an old notebook anchor on docs/benchmarks.md reaches its row of the index)."""
    links = links_into_benchmarks()
    assert links, "no docs page links into the benchmark pages any more: the pattern is wrong"
    broken = []
    for page, target in links:
        path, _, anchor = target.partition("#")
        dest = (page.parent / path).resolve()
        if not dest.exists() or (anchor and anchor not in anchors(dest)):
            broken.append(f"{page.relative_to(ROOT)}: {target}")
    assert not broken, f"links into the benchmark pages that do not resolve: {broken}"


def module_exists(name: str) -> bool:
    path = ROOT.joinpath(*name.split("."))
    return path.with_suffix(".py").is_file() or (path / "__main__.py").is_file()


@pytest.mark.parametrize("page", pages(), ids=lambda p: p.relative_to(ROOT).as_posix())
def test_quoted_commands_name_existing_modules(page: Path) -> None:
    text = page.read_text()
    missing = []
    for name in sorted(set(MODULE.findall(text))):
        if module_exists(name):
            continue
        last = RETIRED_MODULES.get(name)
        if last and page.name == "history.md" and last in text:
            continue  # a retired script, quoted where its last commit is named
        missing.append(name)
    assert not missing, f"{page.relative_to(ROOT)} quotes commands of modules that do not exist: {missing}"


def test_quoted_modules_found() -> None:
    """The command pattern finds the lab's commands (so the test above checks something)."""
    found = {m for page in pages() for m in MODULE.findall(page.read_text())}
    assert "experiments.lab.random_grid_study" in found and "experiments.lab.bench_pools" in found


def test_history_names_the_last_commit_of_each_retired_piece() -> None:
    text = (PAGES_DIR / "history.md").read_text()
    table = text.split("## Retired backends and scripts", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in table.split("\n") if line.startswith("| ")]
    for what, commit in RETIRED_BACKENDS.items():
        assert any(what in row and f"**{commit}**" in row for row in rows), (
            f"history.md's table of retired pieces has no row for {what} with its last commit {commit}"
        )
