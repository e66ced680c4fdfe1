"""The lab stands apart: every lab script imports (so a refactor of the product cannot break one
unseen), no lab script imports a private name of the product, and nothing outside the lab imports
the lab."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
LAB = ROOT / "experiments" / "lab"
PRODUCT = ("synthesis", "flowtest_env", "agents", "experiments")
LAB_MODULES = sorted(p.stem for p in LAB.glob("*.py") if p.stem != "__init__")


def _imports(path: Path) -> list[tuple[str, list[str]]]:
    """(module, names) of every ``import`` and ``from ... import`` in a file, absolute names."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = ".".join(path.relative_to(ROOT).with_suffix("").parts[:-1])
    found: list[tuple[str, list[str]]] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.extend((a.name, []) for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            found.append((module, [a.name for a in node.names]))
    return found


@pytest.mark.parametrize("name", LAB_MODULES)
def test_every_lab_script_imports(name: str) -> None:
    importlib.import_module(f"experiments.lab.{name}")


@pytest.mark.parametrize("name", LAB_MODULES)
def test_no_lab_script_imports_a_private_name(name: str) -> None:
    private = [
        f"{module}.{n}"
        for module, names in _imports(LAB / f"{name}.py")
        if module.split(".")[0] in PRODUCT and not module.startswith("experiments.lab")
        for n in names
        if n.startswith("_")
    ]
    private += [m for m, _ in _imports(LAB / f"{name}.py") if any(part.startswith("_") and part != "__future__" for part in m.split("."))]
    assert not private, f"experiments/lab/{name}.py imports private names: {private}"


def test_nothing_outside_the_lab_imports_the_lab() -> None:
    offenders = []
    for package in PRODUCT:
        for path in (ROOT / package).rglob("*.py"):
            if LAB in path.parents:
                continue
            for module, names in _imports(path):
                if module.startswith("experiments.lab") or (module == "experiments" and "lab" in names):
                    offenders.append(str(path.relative_to(ROOT)))
    assert not offenders, f"product modules import the lab: {sorted(set(offenders))}"


def test_the_wheel_leaves_the_lab_out() -> None:
    """The packages pyproject.toml installs (the same find as the wheel's) hold the command line
    and the maintainer tools, never the lab."""
    import tomllib

    from setuptools import find_packages  # type: ignore[import-untyped]

    find = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]["packages"]["find"]
    packages = set(find_packages(where=str(ROOT), include=find["include"], exclude=find.get("exclude", [])))
    assert {"experiments", "experiments.cli", "experiments.tools", "synthesis", "flowtest_env", "agents"} <= packages
    assert not [p for p in packages if p.startswith("experiments.lab")], packages


@pytest.mark.parametrize("name", LAB_MODULES)
def test_every_import_of_a_lab_script_resolves(name: str) -> None:
    """Imports inside functions too (a lab script often imports what one measurement needs
    where it runs): each product module and name it asks for exists."""
    missing = []
    for module, names in _imports(LAB / f"{name}.py"):
        if module.split(".")[0] not in PRODUCT:
            continue
        try:
            imported = importlib.import_module(module)
        except ImportError:
            missing.append(module)
            continue
        missing += [f"{module}.{n}" for n in names if n != "*" and not hasattr(imported, n) and not _is_module(f"{module}.{n}")]
    assert not missing, f"experiments/lab/{name}.py imports what does not exist: {missing}"


def _is_module(dotted: str) -> bool:
    try:
        importlib.import_module(dotted)
    except ImportError:
        return False
    return True
