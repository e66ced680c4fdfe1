"""The ``flowtest`` command line.

``flowtest synthesize PROBLEM`` turns a problem (a TOML file or a built-in name) into a
checked test: it prints a summary (or, with ``--json``, exactly the JSON object that
problem-format.md fixes), and can write the test artifact (``--out``) and a picture
(``--plot``). Progress goes to standard error only, so standard output stays clean for
scripts.

Subcommands are registered with :func:`command`: each is a function taking the parsed
arguments and returning an exit code, plus a function that declares its arguments.
Every subcommand gets the same error handling from :func:`main`, which is the single
place that maps FlowTest's exceptions to exit codes:

====  =========================================================================
code  meaning
====  =========================================================================
0     success
1     an unexpected internal error (traceback printed: a FlowTest bug)
2     invalid input (:class:`~synthesis.model.errors.ProblemError`, bad options,
      an output file that exists without ``--force``)
3     inconsistent problem (:class:`~synthesis.model.errors.InconsistentProblem`)
4     a synthesized test failed its independent check
      (:class:`~synthesis.model.errors.CheckFailed`, a FlowTest bug)
5     no solution within the time limit (:class:`TimeoutError`)
130   interrupted (Ctrl-C)
====  =========================================================================

Adding a subcommand (``demo``, ``train``, ``evaluate``, ``bench``) takes one decorated
function, e.g. in this module or in a module imported by it::

    def _demo_arguments(p: argparse.ArgumentParser) -> None:
        p.add_argument("PROBLEM")

    @command("demo", "run a scripted system through a test", _demo_arguments)
    def run_demo(args: argparse.Namespace) -> int:
        ...
        return EXIT_OK
"""

from __future__ import annotations

import argparse
import io
import json
import math
import os
import shutil
import sys
import threading
import time
import traceback
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence, TextIO

import numpy as np

from synthesis import pipeline
from synthesis.model.errors import CheckFailed, InconsistentProblem, ProblemError
from synthesis.routing.solver_control import SolveControl, solves_running, status_line, stdout_guard
from synthesis.artifacts.summary import stop_note

EXIT_OK = 0
EXIT_INTERNAL = 1
EXIT_INVALID = 2
EXIT_INCONSISTENT = 3
EXIT_CHECK_FAILED = 4
EXIT_TIMEOUT = 5
EXIT_INTERRUPTED = 130

PROG = "flowtest"

#: What each :attr:`InconsistentProblem.reason` means, for the one-line error message.
INCONSISTENT_REASONS: dict[str, str] = {
    "unreachable": "the goal is unreachable",
    "unroutable": "the test objective is unroutable",
    "infeasible": "no test agent strategy is feasible",
}


# --------------------------------------------------------------------------- registry


@dataclass(frozen=True)
class Command:
    """A subcommand: its name, one-line help, argument declaration and body."""

    name: str
    help: str
    configure: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int]


#: Subcommands in the order ``flowtest --help`` lists them.
COMMANDS: dict[str, Command] = {}


def command(
    name: str, help: str, configure: Callable[[argparse.ArgumentParser], None]
) -> Callable[[Callable[[argparse.Namespace], int]], Callable[[argparse.Namespace], int]]:
    """Register the decorated function as the subcommand ``name``.

    The function receives the parsed arguments and returns the exit code; it may raise
    the errors listed in the module docstring and :func:`main` maps them to exit codes,
    so subcommands never print tracebacks or call ``sys.exit`` themselves.
    """

    def register(run: Callable[[argparse.Namespace], int]) -> Callable[[argparse.Namespace], int]:
        if name in COMMANDS:
            raise ValueError(f"subcommand {name!r} is registered twice")
        COMMANDS[name] = Command(name, help, configure, run)
        return run

    return register


class ArgumentParser(argparse.ArgumentParser):
    """argparse with FlowTest's error contract: a usage error is one ``error: ...`` line
    on stderr and exit code 2 (argparse would print the usage block first)."""

    def error(self, message: str) -> "typing.NoReturn":  # type: ignore[override]
        _error(f"{self.prog}: {message} (see `{self.prog} --help`)")
        raise SystemExit(EXIT_INVALID)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every registered subcommand."""
    parser = ArgumentParser(
        prog=PROG,
        description="Flow-based synthesis of reactive tests for discrete decision-making systems.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for cmd in COMMANDS.values():
        p = sub.add_parser(cmd.name, help=cmd.help, description=cmd.help)
        cmd.configure(p)
        p.set_defaults(run=cmd.run)
    return parser


# --------------------------------------------------------------------------- progress


class StageProgress:
    """Stage messages on standard error, with a live elapsed-time indicator on a TTY.

    Called with a message, it starts a new stage. On a terminal the stage is one line
    that a small background thread rewrites (``\\r``) with the stage's elapsed time once
    the stage has run longer than ``delay`` seconds, so a long MILP solve visibly
    progresses; elsewhere (a file, a pipe, a CI log) each stage is printed once as a
    plain line, because carriage returns make logs unreadable. Nothing is ever written
    to standard output.

    ``status`` (e.g. :func:`synthesis.routing.solver_control.status_line`) says how a running
    solve stands: its best test so far, the bound and the gap. On a terminal it is shown on
    the live line; elsewhere it is printed as a plain line every ``every`` seconds when
    ``every`` is given (``flowtest synthesize --progress``), else not at all.

    Use it as a context manager so the indicator thread always stops and the last line
    is terminated, even when synthesis raises.
    """

    PREFIX = f"{PROG}: "

    def __init__(
        self,
        stream: TextIO | None = None,
        *,
        enabled: bool = True,
        live: bool | None = None,
        delay: float = 1.0,
        interval: float = 0.2,
        status: Callable[[], str | None] | None = None,
        every: float | None = None,
    ) -> None:
        self.stream: TextIO = stream if stream is not None else sys.stderr
        self.enabled = enabled
        if live is None:
            isatty = getattr(self.stream, "isatty", None)
            live = bool(isatty and isatty())
        self.live = enabled and live
        self.delay = delay
        self.interval = interval
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._message: str | None = None  # the stage whose line is still open (live mode)
        self._width = 0  # characters on the open line
        self._started = 0.0
        self._t0 = time.perf_counter()
        self.status = status
        self.every = every if enabled and not self.live else None
        self._last_status = time.perf_counter()

    # -- context manager
    def __enter__(self) -> "StageProgress":
        if self.live or (self.every is not None and self.status is not None):
            self._thread = threading.Thread(target=self._tick, name="flowtest-progress", daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- stages
    def __call__(self, message: str) -> None:
        """Start the stage ``message`` (the ``progress`` callback of synthesis)."""
        if not self.enabled:
            return
        with self._lock:
            self._end_line()
            self._started = time.perf_counter()
            if self.live:
                self._message = message
                self._rewrite(self.PREFIX + message)
            else:
                self._write(self.PREFIX + message + "\n")

    def done(self, message: str) -> None:
        """A final line (e.g. the total time), printed in every mode."""
        if not self.enabled:
            return
        with self._lock:
            self._end_line()
            self._write(self.PREFIX + message + "\n")

    def elapsed(self) -> float:
        """Seconds since this reporter was created."""
        return time.perf_counter() - self._t0

    def close(self) -> None:
        """Stop the indicator thread and terminate the open line."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        with self._lock:
            self._end_line()

    # -- internals (call with the lock held)
    def _end_line(self) -> None:
        if self._message is not None:
            self._rewrite(f"{self.PREFIX}{self._message} ({time.perf_counter() - self._started:.1f} s)")
            self._write("\n")
            self._message = None
            self._width = 0

    def _rewrite(self, line: str) -> None:
        """Replace the open line: fit it to the terminal, blank out what it no longer covers."""
        columns = self._columns() - 1
        if len(line) > columns:
            line = line[: max(columns - 3, 0)] + "..."
        self._write("\r" + line.ljust(self._width))
        self._width = len(line)

    def _write(self, text: str) -> None:
        try:
            self.stream.write(text)
            self.stream.flush()
        except (OSError, ValueError):  # closed or broken stderr: progress is best effort
            self.enabled = False

    def _columns(self) -> int:
        """The width of the terminal behind the stream (stdout may be redirected)."""
        try:
            return os.get_terminal_size(self.stream.fileno()).columns
        except (AttributeError, OSError, ValueError, io.UnsupportedOperation):
            return shutil.get_terminal_size((100, 24)).columns

    def _status(self) -> str | None:
        try:
            return self.status() if self.status is not None else None
        except Exception:  # noqa: BLE001 - a progress line must never end a solve
            return None

    def _tick(self) -> None:
        while not self._stop.wait(self.interval):
            with self._lock:
                if not self.enabled:
                    continue
                if not self.live:  # plain status lines every `every` seconds (--progress)
                    now = time.perf_counter()
                    if self.every is not None and now - self._last_status >= self.every:
                        self._last_status = now
                        status = self._status()
                        if status is not None:
                            self._write(f"{self.PREFIX}{status}\n")
                    continue
                if self._message is None:
                    continue
                elapsed = time.perf_counter() - self._started
                if elapsed >= self.delay:
                    status = self._status()
                    tail = f" | {status}" if status else ""
                    self._rewrite(f"{self.PREFIX}{self._message} ... {elapsed:.1f} s{tail}")


# --------------------------------------------------------------------------- outputs


def _nearest_existing(path: Path) -> Path:
    """``path`` or its closest ancestor that exists (``.`` for a relative path with none)."""
    p = path
    while not p.exists() and not p.is_symlink():
        if p.parent == p:
            break
        p = p.parent
    return p


def _probe_folder(folder: Path, what: str, path: Path) -> None:
    """Raise ProblemError unless a file can be created in ``folder`` (tried, then removed).

    Permission bits lie to root and on read-only mounts; creating a file does not.
    """
    import tempfile

    try:
        fd, name = tempfile.mkstemp(prefix=".flowtest-probe-", dir=folder)
    except OSError as exc:
        raise ProblemError(f"cannot write the {what} {str(path)!r}: {str(folder)!r}: {exc.strerror or exc}") from None
    os.close(fd)
    os.unlink(name)


def check_output_path(path: Path, force: bool, what: str) -> None:
    """Check an output file before any expensive work (raises ProblemError).

    Refused: a folder; a symbolic link (never replaced, even with ``--force``); an
    existing file without ``--force``; a path under a file; a place where nothing can
    be written. Nothing is created.
    """
    if path.is_symlink():
        raise ProblemError(f"{what} {str(path)!r} is a symbolic link; FlowTest never replaces one")
    if path.is_dir():
        raise ProblemError(f"{what} {str(path)!r} is a directory, not a file")
    if path.exists() and not force:
        raise ProblemError(f"{what} {str(path)!r} exists; use --force to overwrite")
    if path.exists() and not path.is_file():
        raise ProblemError(f"{what} {str(path)!r} is not a regular file")
    base = _nearest_existing(path.parent)
    if not base.exists():  # a relative path whose every part is missing: the working folder
        base = Path(".")
    if not base.is_dir():
        raise ProblemError(f"{what} {str(path)!r}: {str(base)!r} is a file, not a folder")
    _probe_folder(base, what, path)


def prepare_output_folder(folder: Path, marker: str, force: bool, what: str, hint: str = "use --force") -> None:
    """Create or accept an output folder FlowTest may write into (raises ProblemError).

    A folder that already holds files FlowTest did not write (no ``marker`` file from an
    earlier run) is refused unless ``force``; a file in its place, or a folder nothing can
    be written into, is refused always. On success the folder exists and holds ``marker``.
    """
    if folder.exists() and not folder.is_dir():
        raise ProblemError(f"{what} {str(folder)!r} exists and is not a folder")
    if folder.is_dir():
        try:
            foreign = any(folder.iterdir()) and not (folder / marker).exists()
        except OSError as exc:
            raise ProblemError(f"cannot read the {what} {str(folder)!r}: {exc.strerror or exc}") from None
        if foreign and not force:
            raise ProblemError(
                f"{what} {str(folder)!r} already holds files FlowTest did not write; {hint} or choose another folder"
            )
    else:
        base = _nearest_existing(folder.parent)
        if base.exists() and not base.is_dir():
            raise ProblemError(f"{what} {str(folder)!r}: {str(base)!r} is a file, not a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ProblemError(f"cannot create the {what} {str(folder)!r}: {exc.strerror or exc}") from None
    _probe_folder(folder, what, folder)
    mark = folder / marker
    if mark.is_symlink():
        raise ProblemError(f"{str(mark)!r} is a symbolic link; FlowTest never replaces one")
    if not mark.exists():
        write_atomically(mark, lambda tmp: tmp.write_text(f"written by FlowTest ({what}); its files may be overwritten by the next run\n"))


def write_atomically(path: Path, write: Callable[[Path], None]) -> None:
    """Create ``path``'s parent directories and write it through a temporary file.

    ``write`` writes a given path; the result replaces ``path`` only once complete, so
    an interrupted run never leaves a truncated artifact or picture behind. A symbolic
    link at ``path`` is never replaced (ProblemError).
    """
    if path.is_symlink():
        raise ProblemError(f"{str(path)!r} is a symbolic link; FlowTest never replaces one")
    if path.is_dir():
        raise ProblemError(f"{str(path)!r} is a directory, not a file")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ProblemError(f"cannot create the directory of {str(path)!r}: {exc.strerror or exc}") from None
    # same directory (so the rename is atomic), same suffix (it picks the picture's format),
    # created by `write` itself so the file gets the user's usual permissions
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.{threading.get_ident()}.tmp{path.suffix}")
    try:
        write(tmp)
        os.replace(tmp, path)
    except OSError as exc:
        raise ProblemError(f"cannot write {str(path)!r}: {exc.strerror or exc}") from None
    finally:
        tmp.unlink(missing_ok=True)


def json_safe(value: Any) -> Any:
    """Plain JSON data: numpy scalars and arrays converted, non-finite floats as ``null``.

    ``json.dumps`` would otherwise fail on numpy integers or write ``Infinity``, which
    is not JSON.
    """
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist())
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, (float, np.floating)):
        v = float(value)
        return v if math.isfinite(v) else None
    return value


# --------------------------------------------------------------------------- human summary


def _state_text(ts: Any, s: int) -> str:
    """A state as people write it: ``(r,c)``, ``(r,c)@fuel`` or the state's name."""
    key = ts.states[s]
    if ts.kind == "grid":
        return f"({key[0]},{key[1]})"
    if ts.kind == "fuel":
        (r, c), f = key
        return f"({r},{c})@{f}"
    return str(key)


def _place_text(ts: Any, p: int) -> str:
    place = ts.places[p]
    if isinstance(place, tuple) and len(place) == 2:
        return f"({place[0]},{place[1]})"
    return str(place)


def _limited(items: Sequence[str], limit: int = 10) -> str:
    if len(items) <= limit:
        return ", ".join(items)
    return ", ".join(items[:limit]) + f", ... ({len(items) - limit} more)"


def _moves_text(ts: Any, mask: np.ndarray) -> list[str]:
    """Restricted moves as ``a -> b``, one per move (fuel levels kept apart)."""
    return [f"{_state_text(ts, int(ts.src[m]))} -> {_state_text(ts, int(ts.dst[m]))}" for m in np.flatnonzero(mask)]


def _walls_text(ts: Any, mask: np.ndarray) -> list[str]:
    """Blocked moves merged by place: ``a | b`` when both directions are blocked."""
    pairs = {(int(ts.place[ts.src[m]]), int(ts.place[ts.dst[m]])) for m in np.flatnonzero(mask)}
    out: list[str] = []
    for a, b in sorted(pairs, key=lambda ab: (str(ts.places[ab[0]]), str(ts.places[ab[1]]))):
        if (b, a) in pairs:
            if str(ts.places[a]) < str(ts.places[b]):
                out.append(f"{_place_text(ts, a)} | {_place_text(ts, b)}")
        else:
            out.append(f"{_place_text(ts, a)} -> {_place_text(ts, b)}")
    return out


def human_summary(test: Any, summary: dict) -> str:
    """A few lines a person reads after ``flowtest synthesize`` (without ``--json``)."""
    p, ts, strategy = test.problem, test.problem.system, test.strategy
    stats = summary["stats"]
    gap = stats.get("mip_gap")
    if summary["status"] == "optimal":
        status = "optimal (proven, gap 0)"
    else:
        status = f"{summary['status']} (gap {'unknown' if gap is None else f'{gap:.2%}'})"
    lines = [
        f"{p.name}: {p.kind} test, {status}{stop_note(summary)}",
        f"  objectives   system: {p.system_objective.text}   test: {p.test_objective.text}",
        f"  flow         {summary['flow']} (edge-disjoint ways through the test)",
        f"  cuts         {summary['n_cuts']} edges of the product graph",
    ]
    reactive = strategy.restrictions & ~strategy.static_obstacles[None, :]
    histories = [q for q in range(strategy.n_hist) if reactive[q].any()]
    if histories:
        lines.append("  restrictions by history (moves the test blocks while the history holds):")
        for q in histories:
            lines.append(f"    {test.spec.history_name(q)} [{test.spec.describe(q)}]: {_limited(_moves_text(ts, reactive[q]))}")
    elif p.kind != "static":
        lines.append("  restrictions none")
    walls = _walls_text(ts, strategy.static_obstacles)
    lines.append(f"  static walls {_limited(walls) if walls else 'none'}")
    if test.agent is not None and "counterexamples" in summary:
        lines.append(f"  test agent   {summary['counterexamples']} counterexample(s)")
    graph = stats["graph"]
    lines.append(
        f"  model        graph {graph['nodes']} nodes / {graph['edges']} edges; MILP {stats['binary_vars']} binary, "
        f"{stats['continuous_vars']} continuous, {stats['constraints']} constraints"
    )
    gap_text = "" if summary["status"] == "optimal" or gap is None else f", gap {gap:.2%}"
    loop = stats.get("agent_seconds")
    if loop:  # the counterexample-guided loop: many MILP solves, GR(1) games, the closed-loop check
        n = len(test.agent.iterations)
        lines.append(
            f"  time         graphs {loop['graphs']:.2f} s, agent loop {loop['total'] - loop['graphs']:.2f} s "
            f"({n} MILP solve(s) {loop['milp']:.2f} s, games and GR(1) {loop['game'] + loop['gr1']:.2f} s, checks "
            f"{loop['verify']:.2f} s){gap_text}; total {loop['total']:.2f} s"
        )
    else:
        lines.append(f"  time         graphs {stats['graph_seconds']:.2f} s, solve {stats['solve_seconds']:.2f} s{gap_text}")
    lines.append(f"  check        bypass flow {summary['bypass_flow']} (must be 0), feasibility flows ok")
    return "\n".join(lines)


# --------------------------------------------------------------------------- synthesize


def _positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of seconds, got {text!r}") from None
    if not math.isfinite(v) or v <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive number of seconds, got {text!r}")
    return v


def _gap(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a relative gap such as 0.01, got {text!r}") from None
    if not (0.0 <= v < 1.0):
        raise argparse.ArgumentTypeError(f"the relative gap must be in [0, 1), got {text!r}")
    return v


def nonnegative_int(text: str) -> int:
    """An argparse type: an integer >= 0 (seeds)."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a non-negative integer, got {text!r}") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"expected a non-negative integer, got {text!r}")
    return v


def positive_int(text: str) -> int:
    """An argparse type: an integer >= 1 (episodes, steps, threads)."""
    return _positive_int(text)


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if v <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return v


#: Seconds between two status lines of ``--progress`` when stderr is not a terminal.
PROGRESS_EVERY = 5.0


def _synthesize_arguments(p: argparse.ArgumentParser) -> None:
    from synthesis.problems.builtins import BUILTINS
    from synthesis.model.strategy import SETTINGS

    p.add_argument(
        "problem",
        metavar="PROBLEM",
        help=f"a TOML problem file, or a built-in problem: {', '.join(BUILTINS)}",
    )
    p.add_argument("--json", action="store_true", help="print the JSON summary of problem-format.md (only it) on stdout")
    p.add_argument("--out", metavar="ARTIFACT", type=Path, help="write the synthesized-test artifact (JSON) here")
    p.add_argument("--plot", metavar="PNG", type=Path, help="draw the test (PNG, SVG or PDF by the file's suffix)")
    p.add_argument("--time-limit", metavar="S", type=_positive_float, help="solver time limit in seconds (default: the problem's, else none)")
    p.add_argument(
        "--after-first", metavar="S", type=_positive_float,
        help="stop S seconds after the first test is found (--time-limit then bounds the time to it; "
        "the paper's budget: --time-limit 600 --after-first 60)",
    )
    p.add_argument("--gap", metavar="G", type=_gap, default=0.0, help="relative MIP gap at which to stop (default 0: prove optimality)")
    p.add_argument("--threads", metavar="N", type=_positive_int, help="solver threads (default 1: the same answer on every machine; at most the machine's CPUs)")
    p.add_argument("--setting", choices=SETTINGS, help="how reactive obstacles are shown (default: the problem's, else instantaneous)")
    p.add_argument("--force", action="store_true", help="overwrite existing --out/--plot files")
    p.add_argument("--no-size-limit", action="store_true",
                   help="synthesize even a problem whose product graph may exceed "
                        f"{pipeline.MAX_GRAPH_EDGES:,} edges (refused by default, with an estimate)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines on stderr")
    p.add_argument(
        "--progress", metavar="S", nargs="?", type=_positive_float, const=PROGRESS_EVERY,
        help="also when stderr is not a terminal (a log, a pipe), print the solver's status (best "
        f"test, bound, gap) on stderr every S seconds (default {PROGRESS_EVERY:g}); on a terminal "
        "the live line always shows it",
    )


@command("synthesize", "synthesize a test for a problem (TOML file or built-in name)", _synthesize_arguments)
def run_synthesize(args: argparse.Namespace) -> int:
    """``flowtest synthesize``: load, synthesize, check, then print and write outputs."""
    from synthesis.artifacts.artifact import artifact_of
    from synthesis.problems.load import load_problem
    from synthesis.artifacts.summary import summary_of

    outputs: list[tuple[Path, str]] = []
    if args.out is not None:
        outputs.append((args.out, "artifact"))
    if args.plot is not None:
        outputs.append((args.plot, "plot"))
    if len(outputs) == 2 and args.out.resolve() == args.plot.resolve():
        raise ProblemError("--out and --plot name the same file")
    for path, what in outputs:  # refuse before spending time on synthesis
        check_output_path(path, args.force, what)
    if args.plot is not None:
        from .plots import check_plot_format

        check_plot_format(args.plot)

    cpus = os.cpu_count() or 1
    if args.threads is not None and args.threads > cpus:
        raise ProblemError(f"--threads {args.threads} is more than the {cpus} CPUs of this machine")
    from synthesis.problems.files import MAX_GRID_CELLS

    max_cells = None if args.no_size_limit else MAX_GRID_CELLS
    problem = _load(lambda name: load_problem(name, max_cells), args.problem)
    control = SolveControl()
    every = getattr(args, "progress", None)
    # stdout is ours: whatever a library prints meanwhile (HiGHS's banner, a C printf)
    # goes to /dev/null, and only our summary reaches the real stdout, after
    with stdout_guard(), StageProgress(enabled=not args.quiet, status=lambda: status_line(control), every=every) as progress:
        progress(f"synthesizing {problem.name} ({problem.kind} test)")
        options = pipeline.SynthesisOptions(
            time_limit=args.time_limit,
            after_first=args.after_first,
            mip_rel_gap=args.gap,
            threads=args.threads,
            setting=args.setting,
            progress=progress,
            control=control,
            max_graph_edges=None if args.no_size_limit else pipeline.MAX_GRAPH_EDGES,
        )
        test = pipeline.synthesize(problem, options)
        summary = json_safe(summary_of(test))
        if args.out is not None:
            progress(f"writing the artifact {args.out}")
            check_output_path(args.out, args.force, "artifact")
            write_atomically(args.out, artifact_of(test, summary).save)
        if args.plot is not None:
            progress(f"drawing {args.plot}")
            from .plots import plot_test

            check_output_path(args.plot, args.force, "plot")
            write_atomically(args.plot, lambda tmp: plot_test(test, tmp))
        progress.done(f"done in {progress.elapsed():.1f} s")

    if args.json:
        sys.stdout.write(json.dumps(summary, allow_nan=False) + "\n")
    else:
        sys.stdout.write(human_summary(test, summary) + "\n")
    sys.stdout.flush()
    return EXIT_OK


def _load(load_problem: Callable[[str], Any], name: str) -> Any:
    """Load a problem; prefix errors with the file name when the message lacks it."""
    try:
        return load_problem(name)
    except ProblemError as exc:
        message = str(exc)
        if name not in message and Path(name).name not in message and Path(name).exists():
            raise ProblemError(f"{name}: {message}") from None
        raise


# --------------------------------------------------------------------------- main


def _error(message: str) -> None:
    """One line ``error: ...`` on stderr (newlines folded so it stays one line)."""
    _say("error: " + " ".join(str(message).split()))


def _flush_and_exit(code: int) -> None:
    """Flush Python's standard streams and end the process at once (``os._exit``)."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError, AttributeError):
            pass
    os._exit(code)


def _say(line: str) -> None:
    """One line on stderr, best effort (stderr may be closed)."""
    try:
        sys.stderr.write(line + "\n")
        sys.stderr.flush()
    except (OSError, ValueError):
        pass


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the exit code (see the module docstring)."""
    try:
        parser = build_parser()
        args = parser.parse_args(argv)  # usage errors exit 2 via argparse
        return int(args.run(args))
    except KeyboardInterrupt:
        # the user's own act, not an error: one plain line, no traceback
        _say(f"{PROG}: interrupted")
        if argv is None and solves_running():
            # we are the process (the console script), and a solver thread has not
            # reached a point where it notices the stop yet: exiting normally would wait
            # for it at interpreter shutdown, so leave now (outputs are written
            # atomically, so no partial file is left behind)
            _flush_and_exit(EXIT_INTERRUPTED)
        return EXIT_INTERRUPTED
    except ProblemError as exc:
        _error(str(exc))
        return EXIT_INVALID
    except InconsistentProblem as exc:
        meaning = INCONSISTENT_REASONS.get(exc.reason, exc.reason)
        _error(f"inconsistent problem ({exc.reason}): {meaning}: {exc}")
        return EXIT_INCONSISTENT
    except CheckFailed as exc:
        _error(f"FLOWTEST BUG (please report it with the problem): the synthesized test failed its check: {exc}")
        return EXIT_CHECK_FAILED
    except TimeoutError as exc:
        detail = str(exc) or "no solution was found"
        _error(f"time limit reached: {detail}; raise --time-limit or accept a gap with --gap")
        return EXIT_TIMEOUT
    except BrokenPipeError:
        # stdout closed early (e.g. `| head`): not an error worth a traceback
        try:
            sys.stdout = open(os.devnull, "w")
        except OSError:
            pass
        return EXIT_INTERNAL
    except Exception:  # a bug: keep the traceback, it is what a maintainer needs
        traceback.print_exc()
        _error("internal error (a FlowTest bug); the traceback above says where")
        return EXIT_INTERNAL


# Subcommands defined in their own modules register themselves on import.
from . import demo as _demo  # noqa: E402,F401
from . import evaluate as _evaluate  # noqa: E402,F401
from . import train_tester as _train_tester  # noqa: E402,F401


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())

