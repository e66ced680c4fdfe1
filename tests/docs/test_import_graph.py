"""Imports run one way (issue 14): no import circle among FlowTest's modules, and the
packages in the order ``synthesis`` <- ``flowtest_env`` <- ``agents`` <- ``experiments``.

The graph is read from the source, not from a running interpreter: every module of the
four packages is parsed and every import in it is an edge, wherever it stands (module
level, inside a function, under ``if TYPE_CHECKING:``) and however it is written
(absolute, relative, ``importlib.import_module("...")`` with a literal name). A
function-local import breaks no circle at run time, it only hides one, so it counts like
any other. ``from pkg import name`` is an edge to ``pkg.name`` when that is a module and
to ``pkg`` (its ``__init__``) otherwise; importing a module is not counted as an edge to
its parent packages (a package ``__init__`` that re-exports its modules is the public-API
pattern, not a circle), nor is a module's import of itself by name (what a script run as
``__main__`` does so that its functions pickle by reference for Ray workers: no other
module stands between, so no import order can break it). A failure names each circle
with the file and line of each import.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("synthesis", "flowtest_env", "agents", "experiments")
"""FlowTest's packages, lowest first: each may import only the ones before it."""

RANK = {p: i for i, p in enumerate(PACKAGES)}


@dataclass(frozen=True)
class Edge:
    """``source`` imports ``target`` at ``path:line``."""

    source: str
    target: str
    path: str
    line: int
    local: bool

    def __str__(self) -> str:
        where = "function-local " if self.local else ""
        return f"{self.source} -> {self.target} ({where}import at {self.path}:{self.line})"


def module_files() -> dict[str, Path]:
    """Dotted module name -> source file, for every module of the four packages."""
    out: dict[str, Path] = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            out[".".join(parts)] = path
    return out


def _package_of(module: str, path: Path) -> str:
    """The package relative imports in ``module`` start from."""
    return module if path.name == "__init__.py" else module.rpartition(".")[0]


def _resolve(module: str, path: Path, node: ast.ImportFrom) -> str:
    if node.level == 0:
        return node.module or ""
    base = _package_of(module, path).split(".")
    if node.level > 1:
        base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _local_nodes(tree: ast.Module) -> set[int]:
    """ids of the nodes inside a function or method body."""
    inside: set[int] = set()
    for fn in ast.walk(tree):
        if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            inside.update(id(n) for n in ast.walk(fn) if n is not fn)
    return inside


def import_graph() -> list[Edge]:
    """Every import between two modules of the four packages (see the module docstring)."""
    files = module_files()
    known = set(files)

    def owner(name: str) -> str | None:
        """The longest prefix of ``name`` that is one of our modules."""
        parts = name.split(".")
        for k in range(len(parts), 0, -1):
            cand = ".".join(parts[:k])
            if cand in known:
                return cand
        return None

    edges: list[Edge] = []
    for module, path in files.items():
        tree = ast.parse(path.read_text(), filename=str(path))
        local = _local_nodes(tree)
        rel = str(path.relative_to(ROOT))
        for node in ast.walk(tree):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = _resolve(module, path, node)
                for alias in node.names:
                    sub = f"{base}.{alias.name}"
                    targets.append(sub if sub in known else base)
            elif (
                isinstance(node, ast.Call)
                and isinstance(node.func, ast.Attribute)
                and node.func.attr == "import_module"
                and node.args
                and isinstance(node.args[0], ast.Constant)
                and isinstance(node.args[0].value, str)
            ):
                targets = [node.args[0].value]
            for name in targets:
                target = owner(name)
                if target is not None and target != module:
                    edges.append(Edge(module, target, rel, node.lineno, id(node) in local))
    return edges


def find_cycle(edges: list[Edge]) -> list[Edge] | None:
    """One import circle of the graph as its edges in order, or ``None`` if it has none
    (depth-first search; deterministic: modules and edges in sorted order)."""
    out: dict[str, list[Edge]] = {}
    for e in sorted(edges, key=lambda e: (e.source, e.target, e.line)):
        out.setdefault(e.source, []).append(e)
    WHITE, GREY, BLACK = 0, 1, 2
    colour: dict[str, int] = {}
    stack: list[Edge] = []

    def visit(u: str) -> list[Edge] | None:
        colour[u] = GREY
        for e in out.get(u, []):
            c = colour.get(e.target, WHITE)
            if c == GREY:
                start = next((i for i, s in enumerate(stack) if s.source == e.target), len(stack))
                return stack[start:] + [e]
            if c == WHITE:
                stack.append(e)
                found = visit(e.target)
                if found is not None:
                    return found
                stack.pop()
        colour[u] = BLACK
        return None

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10_000))
    for u in sorted(out):
        if colour.get(u, WHITE) == WHITE:
            found = visit(u)
            if found is not None:
                return found
    return None


def strongly_connected(edges: list[Edge]) -> list[set[str]]:
    """The groups of modules that import each other, directly or not (Tarjan's
    strongly connected components with more than one module)."""
    succ: dict[str, list[str]] = {}
    for e in edges:
        succ.setdefault(e.source, []).append(e.target)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    groups: list[set[str]] = []

    def visit(u: str) -> None:
        index[u] = low[u] = len(index)
        stack.append(u)
        on_stack.add(u)
        for v in succ.get(u, []):
            if v not in index:
                visit(v)
                low[u] = min(low[u], low[v])
            elif v in on_stack:
                low[u] = min(low[u], index[v])
        if low[u] == index[u]:
            group = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                group.add(w)
                if w == u:
                    break
            if len(group) > 1:
                groups.append(group)

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10_000))
    for u in sorted(succ):
        if u not in index:
            visit(u)
    return sorted(groups, key=sorted)


def circles(edges: list[Edge]) -> list[tuple[set[str], list[Edge]]]:
    """Every group of modules that import each other (:func:`strongly_connected`), with
    one circle through it."""
    out = []
    for group in strongly_connected(edges):
        cycle = find_cycle([e for e in edges if e.source in group and e.target in group])
        assert cycle is not None
        out.append((group, cycle))
    return out


@pytest.fixture(scope="module")
def graph() -> list[Edge]:
    return import_graph()


def test_the_graph_sees_every_kind_of_import(graph: list[Edge]) -> None:
    """The reader is not blind: module-level, relative and function-local imports all
    appear (so an empty cycle report means something)."""
    assert len(module_files()) > 40
    kinds = {(e.local, e.source.split(".")[0] == e.target.split(".")[0]) for e in graph}
    assert (False, True) in kinds and (True, True) in kinds and (False, False) in kinds
    sources = {e.source for e in graph}
    assert all(any(s == p or s.startswith(p + ".") for s in sources) for p in PACKAGES)


def test_find_cycle_names_a_circle_and_accepts_a_dag() -> None:
    """The search itself: it finds a circle through a function-local edge and names it in
    order, and finds none in a graph without one."""
    e = [
        Edge("p.a", "p.b", "p/a.py", 1, False),
        Edge("p.b", "p.c", "p/b.py", 2, False),
        Edge("p.c", "p.a", "p/c.py", 9, True),
        Edge("p.c", "p.d", "p/c.py", 3, False),
    ]
    cycle = find_cycle(e)
    assert cycle is not None and [x.source for x in cycle] == ["p.a", "p.b", "p.c"] and cycle[-1].target == "p.a"
    assert find_cycle(e[:2] + e[3:]) is None
    two = e + [Edge("q.x", "q.y", "q/x.py", 1, False), Edge("q.y", "q.x", "q/y.py", 1, True)]
    assert strongly_connected(two) == [{"p.a", "p.b", "p.c"}, {"q.x", "q.y"}]
    assert [len(c) for _, c in circles(two)] == [3, 2] and circles(e[:2] + e[3:]) == []


def test_no_import_circle(graph: list[Edge]) -> None:
    """No module imports itself back through others; the message names one circle per
    group of modules that import each other, each import with its file and line."""
    found = circles(graph)
    report = "\n".join(
        f"circle {i + 1} (modules that import each other: {', '.join(sorted(group))}), for instance:\n  " + "\n  ".join(map(str, cycle))
        for i, (group, cycle) in enumerate(found)
    )
    assert not found, f"{len(found)} import circle(s):\n{report}"


def test_no_circle_among_sub_packages(graph: list[Edge]) -> None:
    """Sub-packages are layers (``synthesis/`` by stage, each importing only
    downward): with each module counted as its sub-package (``synthesis.routing.solve`` as
    ``synthesis.routing``; a top-level module such as ``synthesis.pipeline`` as itself),
    no two import each other. Modules without a circle can still make one between their
    sub-packages, so this is a check of its own."""

    def unit(module: str) -> str:
        return ".".join(module.split(".")[:2])

    units = [Edge(unit(e.source), unit(e.target), e.path, e.line, e.local) for e in graph if unit(e.source) != unit(e.target)]
    found = circles(units)
    report = "\n".join(
        f"sub-packages that import each other: {', '.join(sorted(group))}, for instance:\n  " + "\n  ".join(map(str, cycle)) for group, cycle in found
    )
    assert not found, report


def test_packages_import_one_way(graph: list[Edge]) -> None:
    """``synthesis`` <- ``flowtest_env`` <- ``agents`` <- ``experiments``: no import runs
    back up the order."""
    upward = [e for e in graph if RANK[e.target.split(".")[0]] > RANK[e.source.split(".")[0]]]
    assert not upward, "imports against the package order:\n  " + "\n  ".join(map(str, upward))


CLI = "experiments.cli"
"""The command line: the console script, the parser, its plumbing and one module per command."""


def command_modules() -> set[str]:
    """The modules of ``experiments/cli`` that hold a command: those whose source assigns
    ``COMMAND`` (:class:`experiments.cli.command.Command`, one per module), read from the source."""
    found = set()
    for module, path in module_files().items():
        if not module.startswith(CLI + "."):
            continue
        tree = ast.parse(path.read_text(), filename=str(path))
        for node in tree.body:
            targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(node, ast.AnnAssign) else []
            if any(isinstance(t, ast.Name) and t.id == "COMMAND" for t in targets):
                found.add(module)
    return found


def command_crossings(edges: list[Edge], commands: set[str]) -> list[Edge]:
    """The imports of one command module by another (a command's library belongs outside
    ``experiments/cli``, where every command and user can import it)."""
    return [e for e in edges if e.source in commands and e.target in commands and e.source != e.target]


def test_command_modules_do_not_import_each_other(graph: list[Edge]) -> None:
    """Each command module parses its arguments, calls the library and maps errors to exit
    codes: ``demo`` and ``benchmark`` import ``experiments.evaluation`` and
    ``experiments.training``, never ``experiments.cli.evaluate`` or ``experiments.cli.train``.
    The check itself finds a crossing when there is one."""
    commands = command_modules()
    assert {f"{CLI}.{name}" for name in ("synthesize", "demo", "evaluate", "train", "train_tester", "benchmark", "serve")} <= commands
    crossings = command_crossings(graph, commands)
    assert not crossings, "command modules import other command modules:\n  " + "\n  ".join(map(str, crossings))
    fake = [
        Edge(f"{CLI}.demo", f"{CLI}.evaluate", "experiments/cli/demo.py", 3, False),
        Edge(f"{CLI}.demo", f"{CLI}.arguments", "experiments/cli/demo.py", 4, False),
    ]
    assert command_crossings(fake, commands) == fake[:1]


def test_the_library_does_not_import_the_command_line(graph: list[Edge]) -> None:
    """The library lies under the command line: no product module outside ``experiments/cli``
    imports one inside it (``python -m experiments``, which runs the command line, aside; the
    lab's measurement scripts may drive the command line as a user does)."""
    drivers = ("experiments.__main__", "experiments.lab")
    upward = [e for e in graph if e.target.startswith(CLI) and not e.source.startswith((CLI, *drivers))]
    assert not upward, "modules outside experiments/cli import it:\n  " + "\n  ".join(map(str, upward))


def test_synthesis_does_not_import_the_environment_libraries() -> None:
    """``synthesis`` computes tests; Gymnasium, PettingZoo and the learners are the other
    packages' business (docs/architecture.md)."""
    banned = ("gymnasium", "pettingzoo", "torch", "stable_baselines3", "sb3_contrib", "matplotlib")
    found = []
    for path in sorted((ROOT / "synthesis").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            names = (
                [a.name for a in node.names]
                if isinstance(node, ast.Import)
                else ([node.module or ""] if isinstance(node, ast.ImportFrom) and node.level == 0 else [])
            )
            found += [f"{path.relative_to(ROOT)}:{node.lineno} imports {n}" for n in names if n.split(".")[0] in banned]
    assert not found, "\n".join(found)


@pytest.mark.slow
def test_every_module_imports_alone() -> None:
    """Each module imports in a fresh interpreter of its own (an order-dependent circle
    that the static graph could miss would fail here with an ImportError). ``__main__``
    modules are scripts (``python -m package``): importing one runs it."""
    failed = []
    for module in sorted(m for m in module_files() if not m.endswith(".__main__")):
        r = subprocess.run([sys.executable, "-c", f"import {module}"], cwd=ROOT, capture_output=True, text=True)
        if r.returncode != 0:
            failed.append(f"{module}: {r.stderr.strip().splitlines()[-1] if r.stderr.strip() else r.returncode}")
    assert not failed, "\n".join(failed)
