"""The method the code cites is in the repository, and every citation resolves.

Docstrings and comments of the product code (``synthesis``, ``flowtest_env``, ``agents``,
``experiments`` but its lab) cite ``docs/method.md §N``, the constraints of the
routing MILP (``c1`` .. ``c14``), the test agent's assumptions and guarantees (``a1`` .. ``a5``,
``g1`` .. ``g8``), ``docs/method.md#anchor`` and the method's notation (``G_sys``, ``Gr(q)``,
``T_TA``, ...). Each must name a section, label or definition that docs/method.md has, under an
anchor that does not change with a title. One convention: the page is always cited by its path,
``docs/method.md``, never a bare ``method.md``.

The product code also carries no development-history tag ("issue 18", "session 11", "issue 16,
point 1"): where a change came from belongs in the commit message and the docs, not in the code.

Each checker returns its findings as ``path:line: message`` strings; the tests assert the product
code has none, and run the checkers on bad text too, so a checker that finds nothing can fail.
"""

from __future__ import annotations

import ast
import io
import re
import tokenize
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cache
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
METHOD = ROOT / "docs" / "method.md"
PRODUCT = ("synthesis", "flowtest_env", "agents", "experiments")
LAB = ROOT / "experiments" / "lab"
"""The measurement scripts (not installed, not product code)."""

#: Labels docs/method.md must define: the routing MILP's constraints, the GR(1) game's
#: assumptions on the SUT and the test agent's guarantees.
LABELS = {f"c{i}" for i in range(1, 15)} | {f"a{i}" for i in range(1, 6)} | {f"g{i}" for i in range(1, 9)}

#: The method's notation and terms as the code writes them, and the anchor of docs/method.md that
#: defines each. A docstring or comment that uses one relies on that definition.
TERMS: dict[str, str] = {
    r"\bT_TA\b": "def-t-ta",
    r"\bB_pi\b": "def-specification-product",
    r"\bG_sys\b": "def-system-product",
    r"\bTgt_sys\b": "def-target",
    r"\bGr\(q\)": "def-gr",
    r"\bC\(q\)": "def-restrictions",
    r"\bR\(q\)": "def-reactive-restrictions",
    r"\bE\(I\)": "def-edges-at-i",
    r"\bE_static\b": "def-static-area",
    r"\bd_state\b": "c11",
    r"\bSrc\b": "def-source",
    r"\bTgt\b": "def-target",
    r"\bH\(s\)": "def-harness",
    r"(?i)\bvirtual product\b": "def-virtual-product",
    r"(?i)\bsystem product\b": "def-system-product",
    r"(?i)\bspecification product\b": "def-specification-product",
    r"(?i)\bintermediate nodes?\b": "def-intermediate",
    r"(?i)\bentry nodes?\b": "def-entry-node",
    r"(?i)\bcut groups?\b": "def-cut-group",
    r"(?i)\bhistor(?:y|ies)\b": "def-history",
    r"(?i)\brestrictions\b": "def-restrictions",
    r"(?i)\bstatic obstacles?\b": "def-static-obstacles",
    r"(?i)\breactive obstacles?\b": "def-reactive-obstacles",
    r"(?i)\bstatic area\b": "def-static-area",
    r"(?i)\btest agent\b": "def-test-agent",
    r"(?i)\bpark(?: state)?s?\b": "def-park",
    r"(?i)\bbypass flow\b": "def-bypass-flow",
    r"(?i)\bMILP-(?:static|reactive|mixed)\b": "def-milp-variants",
    r"(?i)\bMILP-agent\b": "def-milp-agent",
    r"(?i)\bcounterexample(?:-guided)? loop\b": "def-counterexample-loop",
    r"(?i)\btest strateg(?:y|ies)\b": "def-test-strategy",
    r"(?i)\b(?:unreachable|unroutable)\b": "def-inconsistent",
}

_ANCHOR = re.compile(r'<a id="([\w-]+)"></a>')
_HEADING = re.compile(r"^## §(\d+) ", re.M)
_LINK = re.compile(r"\]\(#([\w-]+)\)")
# "§5", "§3-4", "§6–7", "§5/§7", "§5, §7" (a list or range of sections after one §)
_SECTIONS = re.compile(r"§\s*(\d+)((?:\s*(?:[-–/,]|and)\s*§?\s*\d+)*)")
_SECTION_WORD = re.compile(r"method\.md,?\s+section\s+(\d+)")
# "c7", "(c6-c8)", "c4-c5", "c1–c8", "g5-g7", "g6/g7"; not "c5_mask", "c2c" nor "a0" (a start state)
_LABEL = re.compile(r"(?<![\w.])([cag])([1-9]\d*)(?:\s*[-–]\s*\1?(\d+))?(?![\w])")
_METHOD_FILE = re.compile(r"(?<![\w/.-])((?:[\w.-]+/)*)method\.md(#[\w-]+)?")
#: Development-history tags: "issue 18", "issue #18", "issues 16 and 18", "session 11",
#: "point 4 of ...", "(issue 18, point 4)".
HISTORY = re.compile(r"(?i)\bissues?\s*#?\d+(?:,\s*points?\s+\d+)?|\bsessions?\s+\d+|\bpoint\s+\d+\s+of\b|\bissue's\b")


@dataclass(frozen=True)
class Method:
    """What docs/method.md defines: its section numbers and anchors."""

    sections: frozenset[int]
    anchors: frozenset[str]


def read_method(text: str) -> Method:
    """The sections (``## §N`` headings, each with the anchor ``sN`` right before it) and the
    anchors of a method page."""
    anchors = frozenset(_ANCHOR.findall(text))
    sections = frozenset(int(n) for n in _HEADING.findall(text))
    return Method(sections, anchors)


@cache
def method() -> Method:
    return read_method(METHOD.read_text())


def doc_texts(source: str) -> Iterator[tuple[int, str]]:
    """``(first line, text)`` of each docstring, string statement and comment of a module."""
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str):
            yield node.lineno, node.value.value
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            yield tok.start[0], tok.string


def _line(start: int, text: str, pos: int) -> int:
    return start + text.count("\n", 0, pos)


def check_references(path: str, source: str, page: Method) -> list[str]:
    """Findings for the citations of the method in one module's docstrings and comments:
    a citation of a bare ``method.md`` (or any path but ``docs/method.md``), a section, label or
    anchor the page does not have, a term whose definition the page lacks."""
    found: list[str] = []
    for start, text in doc_texts(source):
        for m in _METHOD_FILE.finditer(text):
            if m.group(1) != "docs/":
                found.append(f"{path}:{_line(start, text, m.start())}: cite the method as docs/method.md, not {m.group(0)!r}")
            if m.group(2) and m.group(2)[1:] not in page.anchors:
                found.append(f"{path}:{_line(start, text, m.start())}: docs/method.md has no anchor {m.group(2)!r}")
        for m in _SECTIONS.finditer(text):
            numbers = [int(m.group(1)), *map(int, re.findall(r"\d+", m.group(2)))]
            if "-" in m.group(2) or "–" in m.group(2):
                numbers = list(range(min(numbers), max(numbers) + 1))
            for n in numbers:
                if n not in page.sections:
                    found.append(f"{path}:{_line(start, text, m.start())}: docs/method.md has no §{n} ({m.group(0)!r})")
        for m in _SECTION_WORD.finditer(text):
            if int(m.group(1)) not in page.sections:
                found.append(f"{path}:{_line(start, text, m.start())}: docs/method.md has no section {m.group(1)}")
        for m in _LABEL.finditer(text):
            kind, first, last = m.group(1), int(m.group(2)), int(m.group(3) or m.group(2))
            for n in range(first, last + 1):
                if f"{kind}{n}" not in page.anchors:
                    found.append(f"{path}:{_line(start, text, m.start())}: docs/method.md has no label {kind}{n} ({m.group(0)!r})")
        for pattern, anchor in TERMS.items():
            m2 = re.search(pattern, text)
            if m2 and anchor not in page.anchors:
                found.append(f"{path}:{_line(start, text, m2.start())}: docs/method.md does not define {m2.group(0)!r} (#{anchor})")
    return found


def check_history(path: str, source: str) -> list[str]:
    """Findings for development-history tags anywhere in one module (code, strings, comments)."""
    return [f"{path}:{i}: development-history tag {m.group(0)!r}" for i, line in enumerate(source.splitlines(), 1) for m in HISTORY.finditer(line)]


def product_modules() -> list[Path]:
    files = sorted(p for top in PRODUCT for p in (ROOT / top).rglob("*.py") if LAB not in p.parents)
    assert len(files) > 50, f"found only {len(files)} product modules under {PRODUCT}"
    return files


# --- docs/method.md itself ---------------------------------------------------------------------


def test_the_page_numbers_its_sections_and_labels() -> None:
    """Sections §1..§N in order, each with its anchor ``sN``; every label and internal link resolves."""
    text = METHOD.read_text()
    page = method()
    numbers = [int(n) for n in _HEADING.findall(text)]
    assert numbers == list(range(1, len(numbers) + 1)) and len(numbers) >= 8, numbers
    for n in numbers:
        assert re.search(rf'<a id="s{n}"></a>\n## §{n} ', text), f"§{n} has no anchor s{n} on the line before its heading"
    assert not LABELS - page.anchors, f"docs/method.md lacks labels {sorted(LABELS - page.anchors)}"
    broken = sorted(set(_LINK.findall(text)) - page.anchors)
    assert not broken, f"docs/method.md links to anchors it does not have: {broken}"
    dup = sorted(a for a in page.anchors if len(re.findall(rf'<a id="{a}"></a>', text)) > 1)
    assert not dup, f"anchors defined twice: {dup}"


def test_every_term_the_checker_knows_is_defined() -> None:
    missing = sorted(set(TERMS.values()) - method().anchors)
    assert not missing, f"docs/method.md lacks the definitions {missing}"


# --- the product code's citations ----------------------------------------------------------------


def test_every_method_reference_in_product_code_resolves() -> None:
    page = method()
    found = [f for p in product_modules() for f in check_references(str(p.relative_to(ROOT)), p.read_text(), page)]
    assert not found, "unresolved or miswritten references to the method:\n" + "\n".join(found)


def test_product_code_cites_the_method() -> None:
    """The citations exist at all (a scanner that reads nothing would pass the test above)."""
    cites = sum(p.read_text().count("docs/method.md") for p in product_modules())
    assert cites >= 30, f"only {cites} citations of docs/method.md in product code"


def test_no_development_history_tag_in_product_code() -> None:
    found = [f for p in product_modules() for f in check_history(str(p.relative_to(ROOT)), p.read_text())]
    assert not found, "development-history tags belong in commit messages and docs:\n" + "\n".join(found)


# --- the other docs ----------------------------------------------------------------------------


def test_the_docs_cite_the_method_in_the_repository() -> None:
    """The README and the docs pages point at docs/method.md (not at a copy outside the
    repository), and every section of it they cite exists."""
    page = method()
    found = []
    for path in [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]:
        rel = path.relative_to(ROOT)
        for i, line in enumerate(path.read_text().splitlines(), 1):
            if re.search(r"\.\./[\w./-]*method\.md", line):
                found.append(f"{rel}:{i}: cites a method page outside the repository; the method is docs/method.md")
            for m in re.finditer(r"method\.md,?\s*§\s*(\d+)((?:\s*[-–/,]\s*§?\s*\d+)*)", line):
                for n in [int(m.group(1)), *map(int, re.findall(r"\d+", m.group(2)))]:
                    if n not in page.sections:
                        found.append(f"{rel}:{i}: docs/method.md has no §{n}")
    assert not found, "\n".join(found)


# --- the checkers fail on bad text ---------------------------------------------------------------

_BAD = '''"""Module (docs/method.md §9), constraints c15 and (g3-g9), anchor docs/method.md#nowhere.

A bare method.md §5, the shared ../shared/method.md, and method.md section 12.
"""

X = 1  # see docs/method.md §2-9
'''


def test_the_reference_checker_finds_bad_references() -> None:
    page = read_method('<a id="s1"></a>\n## §1 One\n<a id="s2"></a>\n## §2 Two\n<a id="c1"></a><a id="g3"></a>')
    found = check_references("bad.py", _BAD, page)
    text = "\n".join(found)
    assert "no §9" in text and "no label c15" in text and "no label g4" in text and "no label g9" in text
    assert "no anchor '#nowhere'" in text and "no section 12" in text
    assert "not 'method.md'" in text and "not '../shared/method.md'" in text
    # the comment's range §2-9 is read as 2..9
    assert sum("bad.py:6:" in f and "no §" in f for f in found) == 7, found
    assert not [f for f in found if "no label g3" in f or "no §1 " in f or "no §2 " in f]


def test_the_reference_checker_finds_an_undefined_term() -> None:
    found = check_references("bad.py", '"""The virtual product G and its ``Gr(q)``."""\n', read_method(""))
    assert any("def-virtual-product" in f for f in found) and any("def-gr" in f for f in found), found


def test_the_reference_checker_passes_good_references() -> None:
    good = '"""Rows c4-c5 and c6–c8 (docs/method.md §5, §7; docs/method.md §3-4); g6/g7."""\nc5 = 1  # c5 edges\n'
    assert check_references("good.py", good, method()) == []


def test_the_history_checker_finds_tags() -> None:
    bad = '"""Reductions (issue 18, point 4).\n\nMeasured in Session 11; issue #3; the issue\'s plan."""\n# point 2 of the plan\n'
    found = check_history("bad.py", bad)
    assert len(found) == 5 and "'issue 18, point 4'" in found[0], found
    assert check_history("good.py", '"""A point 3 cells away; the 18 issues of a report; sessions of play."""\n') == []
