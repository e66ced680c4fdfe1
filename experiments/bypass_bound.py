"""Benchmark: lower bounds on a static problem's fewest cuts from an implicit hitting set over
its bypass walks (issue 18: mars-exploration's phase 2).

Usage::

    nice -n 10 .venv/bin/python -m experiments.bypass_bound NAME [--flow F] [--miss ATOM ...]
        [--no-flow] [--rounds N] [--seconds S] [--json FILE]

The routing problem's phase 2 at flow level ``F`` (method.md §5): the cheapest set ``S`` of cut
groups such that no ``Src -> Tgt`` path over the c5 edges (a *bypass walk*, avoiding I) stays
open, and ``F`` edge-disjoint ``Src -> Tgt`` paths over the open model edges remain. This script
bounds it from below with an implicit hitting set loop whose master is a 0-1 model over the
groups alone (OR-Tools CP-SAT, one worker, deterministic):

* a *core* is a minimal set ``C`` of groups such that with every other group closed a bypass
  walk still gets through (a cheapest open walk under the master's answer, shrunk by deletion),
  giving the row ``sum_{g in C} d_g >= 1``; per round and per answer up to
  :data:`CORES_PER_ROUND` group-disjoint cores (each closed before the next search), then
  detours around each group of the first; the answers are the master's optimum and every
  improving answer CP-SAT found on the way to it (cheap non-optimal hitting sets);
* a *flow cut*: when fewer than ``F`` paths survive the master's answer, the minimum cut ``K``
  next to ``Src`` and next to ``Tgt`` gives ``sum_g min(n_g, F)(1 - d_g) + fixed >= F``.

Every row holds for every feasible ``S``, so the master's optimum is a lower bound at each
round; ``--no-flow`` drops the flow cuts and ``--miss ATOM ...`` keeps only the bypass walks
that never enter a state labelled with one of the atoms (both relax the problem: still lower
bounds; on mars-exploration every bypass walk misses one of ``ice``, ``rock``, ``lowfuel``). A master
answer that passes both checks is optimal (``proved``), and a greedy repair of each answer
(close, per open bypass, the cheapest group of its core that keeps flow ``F``) gives checked
incumbents. ``F`` defaults to the maximum flow with every group open (the flow bound; on
mars-exploration and refueling it is the optimum's flow).

The master runs in a child process (``--arrays``): OR-Tools' bundled HiGHS cannot share a
process with highspy, which the model builder loads. Budgets: ``--rounds`` (deterministic)
and ``--seconds`` (wall clock, a benchmark budget checked between rounds). Prints one progress
line per 10 rounds on stderr and the result as JSON on stdout (and to ``--json``).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, dijkstra, maximum_flow

if TYPE_CHECKING:
    from synthesis.problems.problem import Problem

#: Group-disjoint cores harvested per round (then one detour per group of the first).
CORES_PER_ROUND = 30


def arrays_of(problem: Problem, miss: Sequence[str] = ()) -> dict[str, np.ndarray]:
    """What the bound needs of ``problem``'s static routing model: every model edge with its
    master column (``-1``: no binary, or fixed open by the reductions), the group weights,
    Src, Tgt (the flow graph), and the bypass graph: the c5 edges, or with ``miss`` one copy
    of them per atom, without the states labelled with it, under a common source (the bypass
    walks that miss some atom of ``miss``)."""
    from synthesis.graphs.consistency import check_consistency
    from synthesis.pipeline import SynthesisOptions, milp_options
    from synthesis.problems.problem import build_graphs
    from synthesis.routing.model import build_model
    from synthesis.routing.result import required_entries

    _, products = build_graphs(problem)
    options = milp_options(problem, SynthesisOptions())
    if options.mode != "static":
        raise SystemExit(f"error: {problem.name} is not a static problem (mode {options.mode})")
    entries = required_entries(products, options)
    rm = build_model(products, options, entries, check_consistency(products))
    me, groups = rm.edges, rm.groups
    var = np.flatnonzero(me.has_var & ~rm.reductions.fixed_open)
    col_of = np.full(groups.keys.size, -1, dtype=np.int64)
    col_of[var] = np.arange(var.size)
    mcol = col_of[me.grp]
    g = products.virtual
    n, src = g.n_nodes, int(g.initial)
    out = {
        "eu": me.eu, "ev": me.ev, "mcol": mcol, "cost": groups.weight[var].astype(np.int64), "n": np.array(n),
        "src": np.array(src), "target": products.target,
    }
    if not miss:
        c5 = np.flatnonzero(me.c5)
        return {**out, "c5u": me.eu[c5], "c5v": me.ev[c5], "c5col": mcol[c5], "bn": np.array(n), "bsrc": np.array(src), "btarget": products.target}
    us: list[np.ndarray] = []
    vs: list[np.ndarray] = []
    cols: list[np.ndarray] = []
    for k, atom in enumerate(miss):
        labelled = np.array([atom in label for label in products.ts.labels], dtype=bool)
        if not labelled.any():
            raise SystemExit(f"error: no state of {problem.name} is labelled {atom!r}")
        inside = labelled[g.state]
        keep = np.flatnonzero(me.c5 & ~inside[me.eu] & ~inside[me.ev])
        us += [me.eu[keep] + k * n, np.array([len(miss) * n])]  # and an edge from the common source
        vs += [me.ev[keep] + k * n, np.array([src + k * n])]
        cols += [mcol[keep], np.array([-1])]
    return {
        **out, "c5u": np.concatenate(us).astype(np.int64), "c5v": np.concatenate(vs).astype(np.int64),
        "c5col": np.concatenate(cols).astype(np.int64), "bn": np.array(len(miss) * n + 1), "bsrc": np.array(len(miss) * n),
        "btarget": np.append(np.tile(products.target, len(miss)), False),
    }


def bound_in_child(
    arrays: dict[str, np.ndarray], flow: int | None = None, use_flow: bool = True, rounds: int = 10_000, seconds: float | None = None
) -> dict[str, Any]:
    """:meth:`BypassBound.run` in a child process (OR-Tools' bundled HiGHS cannot share a
    process with highspy, which the model builder loads); its result."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "arrays.npz"
        np.savez(path, **arrays)  # type: ignore[arg-type]  # numpy's stub reads ** as allow_pickle
        cmd = [sys.executable, "-m", "experiments.bypass_bound", "--arrays", str(path), "--rounds", str(rounds)]
        cmd += ["--flow", str(flow)] if flow is not None else []
        cmd += ["--seconds", str(seconds)] if seconds is not None else []
        cmd += [] if use_flow else ["--no-flow"]
        out = subprocess.run(cmd, stdout=subprocess.PIPE, text=True, check=True).stdout
    result: dict[str, Any] = json.loads(out)
    return result


def _collector(d: list[Any]) -> Any:
    """A CP-SAT solution callback keeping every improving answer (``bool`` per group of the
    variables ``d``) in its ``found`` list (OR-Tools is imported here: the child's business)."""
    from ortools.sat.python import cp_model

    class Collect(cp_model.CpSolverSolutionCallback):
        def __init__(self) -> None:
            super().__init__()
            self.found: list[np.ndarray] = []

        def on_solution_callback(self) -> None:
            self.found.append(np.array([self.value(x) for x in d], dtype=bool))

    return Collect()


def _is_open(cols: np.ndarray, closed: np.ndarray) -> np.ndarray:
    """``bool`` per edge of master column ``cols`` (``-1``: none, always open): not closed."""
    out: np.ndarray = ~np.append(closed, False)[cols]
    return out


class BypassBound:
    """The implicit hitting set loop of the module docstring, on the arrays of :func:`arrays_of`."""

    def __init__(self, arrays: dict[str, np.ndarray], flow: int | None, use_flow: bool) -> None:
        self.u, self.v, self.col = arrays["c5u"], arrays["c5v"], arrays["c5col"]
        self.eu, self.ev, self.mcol = arrays["eu"], arrays["ev"], arrays["mcol"]
        self.cost = arrays["cost"]
        self.n, self.src = int(arrays["n"]), int(arrays["src"])
        self.tnodes = np.flatnonzero(arrays["target"])
        self.bn, self.bsrc = int(arrays["bn"]), int(arrays["bsrc"])  # the bypass graph
        self.btnodes = np.flatnonzero(arrays["btarget"])
        self.nc = self.cost.size
        self.flow = self.max_flow(np.zeros(self.nc, dtype=bool))[0] if flow is None else flow
        self.use_flow = use_flow
        self.rows: set[tuple[Any, ...]] = set()

    # ------------------------------------------------------------------ checks

    def open_walk(self, closed: np.ndarray) -> np.ndarray | None:
        """The groups on a cheapest open bypass walk (each edge with a group costs 1), or ``None``."""
        col = self.col
        e = np.flatnonzero(_is_open(col, closed))
        w = np.where(col[e] >= 0, 1.0, 1.0 / (e.size + 2))
        n = self.bn
        graph = sp.csr_matrix((w, (self.u[e], self.v[e])), shape=(n, n))
        dist, pred = dijkstra(graph, indices=self.bsrc, return_predecessors=True)
        reached = self.btnodes[np.isfinite(dist[self.btnodes])]
        if reached.size == 0:
            return None
        nodes = [int(reached[np.argmin(dist[reached])])]
        while nodes[-1] != self.bsrc:
            nodes.append(int(pred[nodes[-1]]))
        path = np.array(nodes[::-1])
        a, b = path[:-1], path[1:]
        key = self.u[e].astype(np.int64) * n + self.v[e]
        order = np.lexsort((w, key))
        cols = col[e[order[np.searchsorted(key[order], a.astype(np.int64) * n + b)]]]
        out: np.ndarray = np.unique(cols[cols >= 0])
        return out

    def bypass_open(self, closed: np.ndarray) -> bool:
        """Whether some bypass walk avoids every closed group."""
        col = self.col
        e = np.flatnonzero(_is_open(col, closed))
        graph = sp.csr_matrix((np.ones(e.size, dtype=np.int8), (self.u[e], self.v[e])), shape=(self.bn, self.bn))
        seen = breadth_first_order(graph, self.bsrc, return_predecessors=False)
        return bool(np.isin(self.btnodes, seen).any())

    def core(self, walk: np.ndarray) -> np.ndarray:
        """A minimal subset of ``walk``'s groups that alone (every other group closed) still
        lets a bypass walk through; the costliest groups are tried first for removal."""
        keep = [int(c) for c in walk[np.argsort(-self.cost[walk], kind="stable")]]
        i = 0
        while i < len(keep):
            closed = np.ones(self.nc, dtype=bool)
            closed[keep[:i] + keep[i + 1 :]] = False
            if self.bypass_open(closed):
                del keep[i]
            else:
                i += 1
        return np.array(sorted(keep), dtype=np.int64)

    def max_flow(self, closed: np.ndarray) -> tuple[int, sp.csr_matrix, sp.csr_matrix]:
        """Maximum number of edge-disjoint ``Src -> Tgt`` paths over the open model edges."""
        ok = np.flatnonzero(_is_open(self.mcol, closed))
        t, n = self.tnodes, self.n
        rows = np.concatenate([self.eu[ok], t])
        cols = np.concatenate([self.ev[ok], np.full(t.size, n)])
        caps = np.concatenate([np.ones(ok.size, dtype=np.int32), np.full(t.size, ok.size + 1, dtype=np.int32)])
        cap = sp.csr_matrix((caps, (rows, cols)), shape=(n + 1, n + 1))
        cap.sum_duplicates()
        res = maximum_flow(cap, self.src, n)
        return int(res.flow_value), cap, res.flow

    def flow_cuts(self, closed: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, int]]:
        """Below the flow level: the minimum cuts next to ``Src`` and ``Tgt`` as
        ``(groups, min(count, F), fixed edges)``; else none."""
        value, cap, flow = self.max_flow(closed)
        if value >= self.flow:
            return []
        res = (cap - flow).tocsr()
        res.data = (res.data > 0).astype(np.int8)
        res.eliminate_zeros()
        near = np.zeros(self.n + 1, dtype=bool)
        near[breadth_first_order(res, self.src, return_predecessors=False)] = True
        far = np.zeros(self.n + 1, dtype=bool)
        far[breadth_first_order(res.T.tocsr(), self.n, return_predecessors=False)] = True
        out = []
        for side in (near[: self.n], ~far[: self.n]):
            k = np.flatnonzero(side[self.eu] & ~side[self.ev])
            c = self.mcol[k]
            cols, count = np.unique(c[c >= 0], return_counts=True)
            out.append((cols, np.minimum(count, self.flow), int(np.count_nonzero(c < 0))))
        return out

    def feasible(self, closed: np.ndarray) -> bool:
        """Both checks: no open bypass walk, and (unless ``--no-flow``) the flow level kept."""
        return not self.bypass_open(closed) and (not self.use_flow or self.max_flow(closed)[0] >= self.flow)

    # ------------------------------------------------------------------ the loop

    def cores_of(self, closed: np.ndarray) -> list[np.ndarray]:
        """Group-disjoint cores under ``closed``, then detours around the first's groups."""
        out: list[np.ndarray] = []
        shut = closed.copy()
        while len(out) < CORES_PER_ROUND:
            walk = self.open_walk(shut)
            if walk is None:
                break
            out.append(self.core(walk))
            if walk.size == 0:  # no cut set closes it: the empty row makes the master infeasible
                break
            shut[out[-1]] = True
        for g in out[0].tolist() if out else []:
            shut = closed.copy()
            shut[g] = True
            walk = self.open_walk(shut)
            if walk is not None and walk.size:
                out.append(self.core(walk))
        return out

    def repair(self, closed: np.ndarray) -> np.ndarray | None:
        """Greedy incumbent: per open bypass walk, close the cheapest group of its core that
        keeps the flow level; ``None`` when none does."""
        shut = closed.copy()
        while (walk := self.open_walk(shut)) is not None:
            core = self.core(walk)
            for g in core[np.argsort(self.cost[core], kind="stable")].tolist():
                shut[g] = True
                if not self.use_flow or self.max_flow(shut)[0] >= self.flow:
                    break
                shut[g] = False
            else:
                return None
        return shut

    def run(self, rounds: int, seconds: float | None) -> dict[str, Any]:
        """The loop under the budgets; the bound, the best checked incumbent, and counts.

        Each round separates the master's optimum and every improving answer CP-SAT found on
        the way to it (cheap non-optimal hitting sets: their cores are as valid), then adds
        ``objective >= bound`` (rows are only ever added, so the optimum never falls)."""
        from ortools.sat.python import cp_model

        model = cp_model.CpModel()
        d = [model.new_bool_var(f"d{i}") for i in range(self.nc)]
        objective = sum(int(self.cost[i]) * d[i] for i in range(self.nc))
        model.minimize(objective)
        solver = cp_model.CpSolver()
        solver.parameters.num_workers = 1
        t0, cpu0 = time.perf_counter(), time.process_time()
        closed = np.zeros(self.nc, dtype=bool)
        answers = [closed]
        bound, best, n_cover, n_flow, status, done = 0.0, None, 0, 0, "bound", 0
        master_s = 0.0
        trace: list[dict[str, float]] = []
        for done in range(1, rounds + 1):
            added = 0
            for answer in answers:
                for cols, count, fixed in self.flow_cuts(answer) if self.use_flow else []:
                    key = ("flow", tuple(cols.tolist()), tuple(count.tolist()), fixed)
                    if key not in self.rows:
                        self.rows.add(key)
                        n_flow += 1
                        added += 1
                        model.add(sum(int(c) * (1 - d[g]) for g, c in zip(cols.tolist(), count.tolist(), strict=True)) + fixed >= self.flow)
                for c in self.cores_of(answer):
                    key = ("cover", *c.tolist())
                    if key not in self.rows:
                        self.rows.add(key)
                        n_cover += 1
                        added += 1
                        model.add_bool_or([d[g] for g in c.tolist()])
            if self.feasible(closed):  # the master's optimum passes both checks
                best, status = closed.copy(), "proved"
                break
            if not added:
                raise RuntimeError("a master answer fails a check but gives no new row")
            repaired = self.repair(closed)
            if repaired is not None and self.feasible(repaired) and (best is None or self.cost[repaired].sum() < self.cost[best].sum()):
                best = repaired
            model.clear_hints()
            for i in range(self.nc):
                model.add_hint(d[i], bool(closed[i]))
            collect = _collector(d)
            t1 = time.perf_counter()
            result = solver.solve(model, collect)
            master_s += time.perf_counter() - t1
            if result != cp_model.OPTIMAL:
                status = "infeasible"
                break
            closed = np.array([solver.value(x) for x in d], dtype=bool)
            answers = [closed] + [a for a in collect.found[:-1] if not np.array_equal(a, closed)]
            bound = solver.objective_value
            model.add(objective >= int(round(bound)))
            elapsed = time.perf_counter() - t0
            if done % 10 == 0:
                trace.append({"round": done, "bound": bound, "seconds": elapsed, "cpu": time.process_time() - cpu0, "master": master_s})
                line = f"round {done}: bound {bound:.0f}, {n_cover} cover, {n_flow} flow rows, {elapsed:.1f} s ({master_s:.1f} master)"
                print(line, file=sys.stderr, flush=True)
            if best is not None and bound >= self.cost[best].sum():
                status = "proved"
                break
            if seconds is not None and elapsed >= seconds:
                break
        if status == "proved" and best is not None:
            bound = float(self.cost[best].sum())
        return {
            "status": status,
            "flow": self.flow,
            "bound": bound,
            "incumbent": None if best is None else int(self.cost[best].sum()),
            "incumbent_groups": None if best is None else np.flatnonzero(best).tolist(),
            "rounds": done,
            "cover_rows": n_cover,
            "flow_rows": n_flow,
            "seconds": time.perf_counter() - t0,
            "master_seconds": master_s,
            "cpu_seconds": time.process_time() - cpu0,
            "trace": trace,
        }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m experiments.bypass_bound", description=__doc__.splitlines()[0])
    parser.add_argument("name", nargs="?", help="a built-in or problem file (static)")
    parser.add_argument("--flow", type=int, default=None, help="flow level (default: the flow bound)")
    parser.add_argument("--miss", nargs="+", default=(), metavar="ATOM", help="only bypass walks that miss some ATOM (never enter a state labelled with it)")
    parser.add_argument("--no-flow", action="store_true", help="drop the flow condition (the bypass cover alone)")
    parser.add_argument("--rounds", type=int, default=10_000, help="round budget (deterministic)")
    parser.add_argument("--seconds", type=float, default=None, help="wall-clock budget, checked between rounds")
    parser.add_argument("--json", type=Path, default=None, help="also write the result here")
    parser.add_argument("--arrays", type=Path, default=None, help=argparse.SUPPRESS)  # the child's input
    args = parser.parse_args(argv)
    if args.arrays is not None:
        with np.load(args.arrays) as data:
            arrays = {k: data[k] for k in data.files}
        result = BypassBound(arrays, args.flow, not args.no_flow).run(args.rounds, args.seconds)
        print(json.dumps(result))
        return 0
    if args.name is None:
        parser.error("a problem name is needed")
    from synthesis.problems.load import load_problem

    arrays = arrays_of(load_problem(args.name), args.miss)
    out = bound_in_child(arrays, args.flow, not args.no_flow, args.rounds, args.seconds)
    result = {"problem": args.name, "miss": list(args.miss), "no_flow": args.no_flow, **out}
    if args.json is not None:
        args.json.write_text(json.dumps(result, indent=1) + "\n")
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
