"""One name for every problem: a built-in by its name, or a problem file by its path."""

from __future__ import annotations

from pathlib import Path

from ..model.errors import ProblemError
from .builtins import BUILTINS
from .files import MAX_FILE_BYTES, MAX_GRID_CELLS, load_problem_file
from .limits import check_file_size
from .problem import Problem


def load_problem(name_or_path: str, max_cells: int | None = MAX_GRID_CELLS) -> Problem:
    """A built-in problem by name, or a TOML file by path (grids up to ``max_cells`` cells).

    Examples
    --------
    >>> from synthesis import load_problem
    >>> problem = load_problem("small-reactive")     # a built-in name, or the path of a .toml file
    >>> problem.kind, problem.system_objective.text, problem.test_objective.text
    ('reactive', 'F goal', 'F I1 & F I2')
    """
    if not isinstance(name_or_path, str) or not name_or_path.strip():
        raise ProblemError("empty problem name: give a TOML file or a built-in name")
    if name_or_path in BUILTINS:
        return BUILTINS[name_or_path]()
    p = Path(name_or_path)
    if p.suffix.lower() == ".toml" or p.exists():
        check_file_size(p, "problem file", MAX_FILE_BYTES)  # by its size, before a byte is read
        return load_problem_file(p, max_cells)
    raise ProblemError(f"unknown problem {name_or_path!r}: not a file, and not a built-in ({', '.join(sorted(BUILTINS))})")
