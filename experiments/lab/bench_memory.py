"""Peak memory of synthesis per product-graph edge (the estimate of ``synthesis.problems.limits``).

Usage::

    python -m experiments.lab.bench_memory            # empty 60x60 and 120x120 grids
    python -m experiments.lab.bench_memory 40 80      # other sizes

Each grid (start and goal in two corners, I1 and I2 in the other two, ``F I1 & F I2``) is
synthesized by ``flowtest synthesize --json --time-limit 60`` in a fresh process; the
peak resident memory of that process (``getrusage``) is divided by the edges of G.
"""

from __future__ import annotations

import json
import resource
import subprocess
import sys
import tempfile
from pathlib import Path


def grid_toml(n: int) -> str:
    rows = []
    for r in range(n):
        row = ["."] * n
        if r == 0:
            row[0], row[-1] = "I1", "T"
        if r == n - 1:
            row[0], row[-1] = "S", "I2"
        rows.append(" ".join(row))
    return (
        f'name = "empty-{n}x{n}"\n[system]\ngrid = """\n' + "\n".join(rows) + '\n"""\nstart = "S"\nterminal = ["T"]\n'
        '[labels]\ngoal = ["T"]\nI1 = ["I1"]\nI2 = ["I2"]\n[objectives]\nsystem = "F goal"\ntest = "F I1 & F I2"\n'
        '[environment]\nkind = "reactive"\n'
    )


def measure(n: int) -> tuple[int, float]:
    """(edges of G, peak MB) of one synthesis in a fresh process."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "grid.toml"
        path.write_text(grid_toml(n))
        before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
        out = subprocess.run(
            [sys.executable, "-m", "experiments", "synthesize", str(path), "--json", "-q", "--time-limit", "60"], capture_output=True, text=True, check=True
        )
        peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    edges = int(json.loads(out.stdout)["stats"]["graph"]["edges"])
    return edges, max(peak, before) / 1024


def main(argv: list[str] | None = None) -> int:
    sizes = [int(a) for a in (argv if argv is not None else sys.argv[1:])] or [60, 120]
    print("| grid | G edges | peak MB | KB per edge |\n|---|---|---|---|")
    for n in sizes:
        edges, mb = measure(n)
        print(f"| {n}x{n} | {edges} | {mb:.0f} | {mb * 1024 / edges:.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
