"""``synthesis`` is layered by stage: every module imports only from its own layer's modules
or from layers below, at module level (no import inside a function, no ``TYPE_CHECKING``).

The order (synthesis/__init__.py says what each holds)::

    model < graphs < problems < routing, checks < test_agent < options, synthesized_test, pipeline < artifacts

``routing`` and ``checks`` are one level and import nothing from each other
(tests/synthesis/test_checks_independent.py).
"""

from __future__ import annotations

import ast
from pathlib import Path

import synthesis

PACKAGE = Path(synthesis.__file__).parent
LAYER = {"model": 0, "graphs": 1, "problems": 2, "routing": 3, "checks": 3, "test_agent": 4, "options": 5, "synthesized_test": 5, "pipeline": 5, "artifacts": 6}


def _part(parts: list[str]) -> str:
    """The layer of a module given its dotted path inside ``synthesis``."""
    return parts[0]


def _synthesis_imports(path: Path) -> list[tuple[ast.stmt, list[str]]]:
    """Each import of another synthesis module in ``path``: (the statement, its path inside synthesis)."""
    rel = path.relative_to(PACKAGE).with_suffix("").parts
    package = ["synthesis", *rel[:-1]]  # the package a relative import starts from
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1]
                mod = base + (node.module.split(".") if node.module else [])
            else:
                mod = (node.module or "").split(".")
            if mod[0] != "synthesis":
                continue
            targets = [mod[1:]] if len(mod) > 1 else [[a.name] for a in node.names]
            out.extend((node, t) for t in targets)
        elif isinstance(node, ast.Import):
            out.extend((node, a.name.split(".")[1:]) for a in node.names if a.name.startswith("synthesis."))
    return out


def _modules() -> list[Path]:
    return sorted(p for p in PACKAGE.rglob("*.py") if p.name != "__init__.py" or p.parent != PACKAGE)


def test_every_stage_imports_only_downward() -> None:
    wrong = []
    for path in _modules():
        rel = list(path.relative_to(PACKAGE).with_suffix("").parts)
        mine = LAYER[_part(rel)]
        for node, target in _synthesis_imports(path):
            if target and LAYER[_part(target)] > mine:
                wrong.append(f"{'/'.join(rel)}.py:{node.lineno} imports synthesis.{'.'.join(target)}")
    assert not wrong, wrong


def test_routing_and_checks_are_independent() -> None:
    for path in _modules():
        rel = list(path.relative_to(PACKAGE).with_suffix("").parts)
        if _part(rel) in ("routing", "checks"):
            other = {"routing": "checks", "checks": "routing"}[_part(rel)]
            assert all(_part(t) != other for _, t in _synthesis_imports(path) if t), path


def test_imports_are_at_module_level() -> None:
    """No import inside a function or under ``if TYPE_CHECKING`` (they hid circles)."""
    hidden = []
    for path in _modules():
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.If)):
                for inner in ast.walk(node):
                    if isinstance(inner, (ast.Import, ast.ImportFrom)):
                        hidden.append(f"{path.relative_to(PACKAGE)}:{inner.lineno}")
    assert not hidden, hidden


def test_the_public_api() -> None:
    assert "synthesize" in synthesis.__all__ and "load_problem" in synthesis.__all__
    for name in synthesis.__all__:
        assert getattr(synthesis, name) is not None, name
