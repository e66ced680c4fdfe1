"""Systems under test written outside FlowTest: a Python planner or a planner process.

Two names put your own system wherever FlowTest names one (``flowtest evaluate --sut``,
``flowtest benchmark --sut``, :func:`experiments.cli.evaluate.evaluate`):

* ``python:MODULE:NAME`` — ``NAME`` in the Python module ``MODULE`` (found from the current
  directory, then ``sys.path``, as ``python -m`` finds modules; ``MODULE`` may also be a
  file, ``python:planners/bfs.py:Planner``). ``NAME`` is either

  - a **planner function** ``act(observation, mask) -> action`` (two parameters), or
  - a **factory**: a class, or a function of zero or one parameter, returning a planner:
    an object with ``act(observation, mask) -> action`` (or callable as such) and,
    optionally, ``reset(seed)`` (called before every run) and ``close()``. A factory of
    one parameter receives the test's public description (the ``test`` of the
    protocol's ``hello`` message below).

* ``cmd:COMMAND`` — a process in any language (``cmd:"python3 planner.py"``,
  ``cmd:"awk -f planner.awk"``), started in the current directory, speaking the JSON-lines
  protocol below on its standard input and output; its standard error is kept for the
  report's message if it fails. ``COMMAND`` is split as a shell would split words
  (``shlex``), with no shell features (write ``cmd:"sh -c '...'"`` for those).

The protocol (one JSON object per line; FlowTest writes compact JSON)
---------------------------------------------------------------------
FlowTest to the planner:

``{"type": "hello", "protocol": "flowtest-planner", "version": 1, "test": {...}}``
    Once, when the process starts. ``test``: ``name``, ``kind`` (``static``, ``reactive``,
    ``mixed``, ``agent``), ``objective`` (the system objective, the SUT's own task; never
    the hidden test objective), ``system`` (the transition system as the artifact writes
    it: ``states``, ``moves``, ``labels``, ``layout``, ...; docs/artifact-schema.md; the
    labels only of the system objective's propositions, as the environments show them),
    ``actions`` (the action names of a grid: ``N S E W stay``; on graphs ``null``: the
    names are given per step), ``max_steps`` and ``agent`` (whether a test agent moves).
``{"type": "reset", "seed": S}``
    A run starts (``seed`` is the run's seed, for a planner that draws random numbers).
``{"type": "step", "step": K, "state": ..., "allowed": [...], "to": [...], "mask": [...], "agent": ...}``
    Answer it. ``state``: the system's state as in problem-format.md (``[row, col]``,
    ``[[row, col], fuel]`` or a state name); ``allowed``: the names of the actions the
    test allows now (``"N"``, ``"stay"``, on graphs ``"-> NAME"``); ``to``: the state each
    allowed action leads to, in the same order; ``mask``: per action index 1 if allowed;
    ``agent``: the test agent's place (``[row, col]`` or a place name), or ``null``.
``{"type": "end", "verdict": {...}}``
    The run ended (the verdict of ``flowtest evaluate``); no answer.

The planner answers every ``step`` with one line: ``{"action": A}``, or ``A`` alone,
where ``A`` is an action index (``0``) or name (``"N"``, ``N``, ``stay``). It must answer
within the step timeout (``--step-timeout``, default :data:`DEFAULT_STEP_TIMEOUT` s; the
first answer includes the process's start) and must choose an allowed action. A planner
that exits, hangs, answers something that is not an action or an action the test does not
allow now **fails the run** (:class:`PlannerError`): the run is reported as the system's
failure with what happened (the exit status and the end of its error output, the step),
and every other system and test still runs. At the end FlowTest closes the planner's
standard input; it should then exit.

A ``python:`` planner receives exactly these ``step`` messages as ``observation`` (a
``dict``; plus ``observation["observation"]``, the Gymnasium environment's observation
array) and ``mask`` as an ``int8`` array; its answer is an index or a name as above.

Examples
--------
A planner process that always takes the last allowed action (``stay`` when it may):

>>> import pathlib, shlex, sys, tempfile
>>> import gymnasium as gym
>>> import flowtest_env
>>> from agents.registry import make_policy
>>> folder = tempfile.TemporaryDirectory()
>>> planner = pathlib.Path(folder.name, "planner.py")
>>> _ = planner.write_text('''
... import json, sys
... for line in sys.stdin:
...     message = json.loads(line)
...     if message["type"] == "step":
...         print(json.dumps({"action": message["allowed"][-1]}), flush=True)
... ''')
>>> env = gym.make("FlowTest-SmallReactive-v0")
>>> policy = make_policy(f"cmd:{shlex.quote(sys.executable)} {shlex.quote(str(planner))}", env)
>>> obs, info = env.reset(seed=0)
>>> policy.reset(0)
>>> policy.act(obs, info)        # the index of "stay"
4
>>> policy.close()
>>> folder.cleanup()
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import json
import os
import queue
import shlex
import shutil
import signal
import subprocess
import sys
import threading
import weakref
from collections import deque
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

import numpy as np

from flowtest_env.game import TestGame
from flowtest_env.runtime import describe

from .base import PolicyError, action_mask_of, game_of, state_index

PROTOCOL = "flowtest-planner"
PROTOCOL_VERSION = 1
DEFAULT_STEP_TIMEOUT = 10.0
"""Seconds a planner may take to answer one step (a ``cmd:`` planner's first answer
includes its start; a ``python:`` planner's ``reset`` is timed as one step)."""

PREFIXES = ("python", "cmd")
"""The name prefixes of systems from outside FlowTest."""


class PlannerError(RuntimeError):
    """A planner failed during a run: it crashed (raised, exited), hung past the step
    timeout, or answered something that is not an allowed action. The run is the
    system's failure; the message says what happened and at which step."""


# --------------------------------------------------------------------------- messages


def _max_steps(env: Any) -> int | None:
    for obj in (env, getattr(env, "unwrapped", None)):
        n = getattr(obj, "max_steps", None)
        if isinstance(n, int):
            return n
    return None


def describe_test(game: TestGame, max_steps: int | None) -> dict[str, Any]:
    """The public description of a test, as a system under test may know it (the
    ``hello`` message's ``test``; :func:`flowtest_env.runtime.describe`): never the hidden
    test objective or the restrictions."""
    return describe(game, max_steps)


def _run_of(env: Any) -> Any:
    for obj in (getattr(env, "unwrapped", None), env):
        run = getattr(obj, "run", None)
        if run is not None and hasattr(run, "system"):
            return run
    return None


class _Messages:
    """Builds the protocol's messages for one env."""

    def __init__(self, env: Any) -> None:
        self.env = env
        self.game = game_of(env)
        self.test = describe_test(self.game, _max_steps(env))
        self.count = 0

    def hello(self) -> dict[str, Any]:
        return {"type": "hello", "protocol": PROTOCOL, "version": PROTOCOL_VERSION, "test": self.test}

    def step(self, observation: Any, info: dict[str, Any]) -> tuple[dict[str, Any], np.ndarray, int]:
        """``(message, mask, state index)`` of the situation now."""
        g = self.game
        mask = np.asarray(action_mask_of(observation, info), dtype=np.int8)
        run = _run_of(self.env)
        if run is not None:
            s, k = int(run.system), int(run.steps)
            agent_state = int(run.agent)
        else:
            s, k, agent_state = state_index(g, info["system_state"]), self.count, -1
        self.count = k + 1
        allowed = [int(a) for a in np.flatnonzero(mask)]
        place = g.agent_place[agent_state] if 0 <= agent_state < g.n_agent_states else -1
        msg = {
            "type": "step",
            "step": k,
            "state": g.state_json(s),
            "allowed": [g.action_name(s, a) for a in allowed],
            "to": [g.state_json(s if a == g.stay_action else int(g.succ_list[s][a])) for a in allowed],
            "mask": mask.tolist(),
            "agent": None if place < 0 else _place_json(g, place),
        }
        return msg, mask, s


def _place_json(game: TestGame, place: int) -> object:
    p = game.ts.places[place]
    return list(p) if isinstance(p, tuple) else p


def parse_answer(answer: Any, game: TestGame, state: int, mask: np.ndarray, step: int, hint: str = "") -> int:
    """The action index a planner's answer names (a ``dict`` with ``action``, an index or
    a name; a protocol line is decoded first).

    Raises
    ------
    PlannerError
        If the answer names no action, or one the test does not allow now.
    """
    raw = answer
    if isinstance(answer, str):
        text = answer.strip()
        try:
            answer = json.loads(text)
        except ValueError:
            answer = text
    if isinstance(answer, dict):
        if "action" not in answer:
            raise PlannerError(f"step {step}: answered {_short(raw)}, an object without \"action\"{hint}")
        answer = answer["action"]
    names = [game.action_name(state, a) for a in range(game.n_actions)]
    action: int | None = None
    if isinstance(answer, (int, np.integer)) and not isinstance(answer, (bool, np.bool_)):
        action = int(answer) if 0 <= int(answer) < game.n_actions else None
    elif isinstance(answer, str):
        word = answer.strip()
        if word in names:
            action = names.index(word)
        elif word.isdigit() and int(word) < game.n_actions:
            action = int(word)
        elif not game.is_grid and f"-> {word}" in names:
            action = names.index(f"-> {word}")
    if action is None:
        raise PlannerError(f"step {step}: answered {_short(raw)}, which is not an action "
                           f"(expected an index 0..{game.n_actions - 1} or one of: {', '.join(names)}){hint}")
    if not mask[action]:
        allowed = ", ".join(names[a] for a in np.flatnonzero(mask))
        raise PlannerError(f"step {step}: chose {names[action]!r}, which the test does not allow now "
                           f"(allowed: {allowed})")
    return action


def _short(x: Any, n: int = 80) -> str:
    """A short quotation of an answer: a line in quotes, a Python value as its ``repr``."""
    if not isinstance(x, str):
        text = repr(x)
        return text if len(text) <= n else text[:n] + "..."
    text = x.strip()
    return repr(text if len(text) <= n else text[:n] + "...")


# --------------------------------------------------------------------------- python:


def _import(module: str) -> Any:
    """Import ``module`` as ``python -m`` would (the current directory first), or load a
    ``.py`` file."""
    cwd = os.getcwd()
    if module.endswith(".py"):
        path = Path(module)
        if not path.is_file():
            raise PolicyError(f"no Python file {module!r} (from {cwd})")
        spec = importlib.util.spec_from_file_location(path.stem, path.resolve())
        if spec is None or spec.loader is None:
            raise PolicyError(f"cannot load {module!r} as a Python module")
        mod = importlib.util.module_from_spec(spec)
        sys.modules.setdefault(path.stem, mod)
        spec.loader.exec_module(mod)
        return mod
    if cwd not in sys.path and "" not in sys.path:
        sys.path.insert(0, cwd)
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        if exc.name and (module == exc.name or module.startswith(exc.name + ".")):
            raise PolicyError(f"no Python module {module!r} (looked in {cwd} and sys.path)") from None
        raise PolicyError(f"module {module!r} could not be imported: {type(exc).__name__}: {exc}") from None
    except Exception as exc:  # the user's module raised while being imported
        raise PolicyError(f"module {module!r} raised while being imported: {type(exc).__name__}: {exc}") from None


def resolve(spec: str) -> Any:
    """The object ``MODULE:NAME`` names (``NAME`` may be dotted: ``Class.method``).

    Raises
    ------
    PolicyError
        On a malformed spec, a missing module or a missing attribute.
    """
    module, sep, name = spec.rpartition(":")
    if not sep or not module or not name:
        raise PolicyError(f"expected python:MODULE:NAME (e.g. python:my_planner:BfsPlanner), not python:{spec}")
    obj = _import(module)
    for part in name.split("."):
        if not hasattr(obj, part):
            raise PolicyError(f"module {module!r} has no attribute {name!r}")
        obj = getattr(obj, part)
    if not callable(obj):
        raise PolicyError(f"{module}:{name} is a {type(obj).__name__}, not a planner function, class or factory")
    return obj


def _n_required(fn: Any) -> int | None:
    """Required positional parameters of ``fn`` (``None`` if unknown)."""
    try:
        sig = inspect.signature(fn)
    except (TypeError, ValueError):
        return None
    kinds = (inspect.Parameter.POSITIONAL_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)
    return sum(p.kind in kinds and p.default is inspect.Parameter.empty for p in sig.parameters.values())


def _accepts_one(fn: Any) -> bool:
    try:
        sig = inspect.signature(fn)
    except (TypeError, ValueError):
        return False
    params = list(sig.parameters.values())
    return any(p.kind == inspect.Parameter.VAR_POSITIONAL for p in params) or any(
        p.kind in (inspect.Parameter.POSITIONAL_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD) for p in params)


def is_planner_function(obj: Any) -> bool:
    """Whether ``obj`` is a planner function ``act(observation, mask)`` rather than a factory
    (a class, or a function of zero or one parameter)."""
    if inspect.isclass(obj):
        return False
    n = _n_required(obj)
    return n is None or n >= 2


def spec_of(obj: Any) -> str | None:
    """The ``python:MODULE:NAME`` that names ``obj`` from the command line, when it is a
    module-level function or class of an importable module (else ``None``)."""
    module = getattr(obj, "__module__", None)
    qual = getattr(obj, "__qualname__", None)
    if not module or not qual or module == "__main__" or "<" in qual:
        return None
    return f"python:{module}:{qual}"


class PythonPlanner:
    """A Python planner as a FlowTest :class:`~agents.base.Policy` (see the module docstring).

    ``target`` is a planner function, a factory, or (from :func:`planner_policy`) a planner
    object itself.
    """

    def __init__(self, name: str, env: Any, target: Any, built: bool = False, step_timeout: float | None = None) -> None:
        self.name = name
        self.timeout = _step_timeout(step_timeout)
        self.messages = _Messages(env)
        self.game = self.messages.game
        if built:
            self.planner: Any = target
        elif is_planner_function(target):
            self.planner = target
        else:
            try:
                self.planner = target(self.messages.test) if _accepts_one(target) else target()
            except Exception as exc:
                raise PolicyError(f"the factory raised {type(exc).__name__}: {exc}") from None
        act = getattr(self.planner, "act", None)
        self._act = act if callable(act) else self.planner
        if not callable(self._act):
            raise PolicyError(f"the factory returned a {type(self.planner).__name__} with no act(observation, mask)")

    def reset(self, seed: int | None = None) -> None:
        self.messages.count = 0
        reset = getattr(self.planner, "reset", None)
        if callable(reset) and reset is not self._act:
            try:
                with _timed(self.timeout):
                    reset(seed)
            except _Overran as exc:
                _keep_interrupt(exc)
                raise PlannerError(f"reset: the planner did not return within {self.timeout:g} s (--step-timeout)") from None
            except Exception as exc:
                raise PlannerError(f"reset raised {type(exc).__name__}: {exc}") from None

    def act(self, observation: Any, info: dict[str, Any]) -> int:
        msg, mask, s = self.messages.step(observation, info)
        msg["observation"] = observation
        try:
            with _timed(self.timeout):
                answer = self._act(msg, mask.copy())
        except _Overran as exc:
            _keep_interrupt(exc)
            raise PlannerError(f"step {msg['step']}: the planner gave no answer within {self.timeout:g} s "
                               "(--step-timeout); it was stopped") from None
        except Exception as exc:
            raise PlannerError(f"step {msg['step']}: raised {type(exc).__name__}: {exc}") from None
        return parse_answer(answer, self.game, s, mask, msg["step"])

    def close(self) -> None:
        close = getattr(self.planner, "close", None)
        if callable(close):
            close()


class _Overran(BaseException):
    """Raised inside a ``python:`` planner's call when its step timer rings: a
    ``BaseException``, so the planner's own ``except Exception`` does not swallow it."""


def _keep_interrupt(exc: _Overran) -> None:
    """A ring while a Ctrl-C unwound the planner's call replaced the ``KeyboardInterrupt``:
    raise that again (the user's stop, not the planner's timeout)."""
    if isinstance(exc.__context__, KeyboardInterrupt):
        raise exc.__context__


def _step_timeout(step_timeout: float | None) -> float:
    timeout = DEFAULT_STEP_TIMEOUT if step_timeout is None else float(step_timeout)
    if not timeout > 0:
        raise PolicyError(f"the step timeout must be positive, not {step_timeout}")
    return timeout


@contextmanager
def _timed(seconds: float) -> Iterator[None]:
    """Interrupt the ``with`` body after ``seconds`` (raising :class:`_Overran` in it), by
    ``SIGALRM``: a Python planner's loop or sleep is stopped, a call into C code that does
    not return is not. Untimed where there is no ``SIGALRM`` (Windows), off the main
    thread, where Python delivers no signals, where a real-time timer is already armed
    (the caller's own, which this one would cancel) and where ``SIGALRM``'s handler was
    installed outside Python (it could not be put back).

    A ring that comes after the body has ended (the timer's last instant, or while a
    ``KeyboardInterrupt`` unwinds it) is ignored: the body's own outcome stands."""
    if (not hasattr(signal, "setitimer") or threading.current_thread() is not threading.main_thread()
            or signal.getitimer(signal.ITIMER_REAL)[0] > 0 or signal.getsignal(signal.SIGALRM) is None):
        yield
        return
    active = [True]

    def ring(signum: int, frame: Any) -> None:
        if active[0]:
            raise _Overran

    old = signal.signal(signal.SIGALRM, ring)
    try:
        signal.setitimer(signal.ITIMER_REAL, seconds)
        yield
    finally:
        while True:  # a ring before the first line here is caught, and the restoring goes on
            try:
                active[0] = False
                signal.setitimer(signal.ITIMER_REAL, 0)
                signal.signal(signal.SIGALRM, old)
                break
            except _Overran:
                continue


def make_python(env: Any, arg: str, step_timeout: float | None = None) -> PythonPlanner:
    """``python:MODULE:NAME``: the planner ``NAME`` of ``MODULE`` for ``env``.

    Raises
    ------
    PolicyError
        If the module or the name is missing, or the factory fails.
    """
    return PythonPlanner(f"python:{arg}", env, resolve(arg), step_timeout=step_timeout)


def planner_policy(obj: Any, env: Any, name: str | None = None, step_timeout: float | None = None) -> PythonPlanner:
    """A planner given as a Python object (a function, a factory, or a planner object with
    ``act(observation, mask)``) as a :class:`~agents.base.Policy` for ``env``; named
    ``name``, else by :func:`spec_of` where it can be, else by its type. Each call of its
    ``act`` and ``reset`` may take ``step_timeout`` seconds (default
    :data:`DEFAULT_STEP_TIMEOUT`; on the main thread of a POSIX process).

    Examples
    --------
    >>> import gymnasium as gym
    >>> import flowtest_env
    >>> from agents.external import planner_policy
    >>> def first_allowed(observation, mask):
    ...     return observation["allowed"][0]     # the name of an action the test allows now
    >>> env = gym.make("FlowTest-SmallReactive-v0")
    >>> policy = planner_policy(first_allowed, env, name="first-allowed")
    >>> obs, info = env.reset(seed=0)
    >>> policy.reset(0)
    >>> policy.name, policy.act(obs, info)       # "N" is action 0
    ('first-allowed', 0)
    """
    label = name or spec_of(obj) or f"python object {getattr(obj, '__qualname__', type(obj).__name__)}"
    if inspect.isclass(obj) or inspect.isfunction(obj) or inspect.ismethod(obj) or not hasattr(obj, "act"):
        return PythonPlanner(label, env, obj, step_timeout=step_timeout)
    return PythonPlanner(label, env, obj, built=True, step_timeout=step_timeout)


# --------------------------------------------------------------------------- cmd:


def command_words(arg: str) -> list[str]:
    """``COMMAND`` split into words, its program found.

    Raises
    ------
    PolicyError
        If the command is empty, unbalanced, or its program is not found.
    """
    try:
        words = shlex.split(arg)
    except ValueError as exc:
        raise PolicyError(f"cannot split the command ({exc})") from None
    if not words:
        raise PolicyError("cmd: needs a command, e.g. cmd:\"python3 planner.py\"")
    prog = words[0]
    if os.sep in prog or (os.altsep and os.altsep in prog):
        if not Path(prog).is_file():
            raise PolicyError(f"no program {prog!r} (from {os.getcwd()})")
        if not os.access(prog, os.X_OK):
            raise PolicyError(f"{prog!r} is not executable (chmod +x, or run it through its interpreter)")
    elif shutil.which(prog) is None:
        raise PolicyError(f"command {prog!r} not found on PATH")
    return words


def _stop(proc: subprocess.Popen[str]) -> None:
    """End a planner process: close its input, give it a moment, then kill it."""
    if proc.poll() is not None:
        return
    try:
        if proc.stdin is not None:
            proc.stdin.close()
    except OSError:
        pass
    try:
        proc.wait(timeout=1.0)
        return
    except subprocess.TimeoutExpired:
        pass
    proc.kill()
    try:
        proc.wait(timeout=2.0)
    except subprocess.TimeoutExpired:  # pragma: no cover - a process that ignores SIGKILL
        pass


LOGS_HINT = "; a planner process answers one line per step on standard output and writes its logs to standard error"
"""Said after an answer line of a process that is not an action: most often a log line."""

MAX_LINE = 1 << 16
"""Longest line read from a planner at once (a longer one arrives in pieces, the first of
which is not an action)."""


def _pump(stream: IO[str], into: queue.Queue[str | None]) -> None:
    while line := stream.readline(MAX_LINE):
        into.put(line)
    into.put(None)


def _keep_tail(stream: IO[str], tail: deque[str]) -> None:
    while line := stream.readline(MAX_LINE):
        tail.append(line.rstrip("\n")[:300])


class CommandPlanner:
    """A planner process speaking the JSON-lines protocol, as a FlowTest
    :class:`~agents.base.Policy` (see the module docstring). The process starts at the
    first run and serves every run of this policy; after a failure the next run starts a
    fresh one. It is ended by :meth:`close` (or when the policy is collected)."""

    def __init__(self, name: str, env: Any, arg: str, step_timeout: float | None = None) -> None:
        self.name = name
        self.words = command_words(arg)
        self.cwd = os.getcwd()
        self.timeout = _step_timeout(step_timeout)
        self.messages = _Messages(env)
        self.game = self.messages.game
        self.proc: subprocess.Popen[str] | None = None
        self.lines: queue.Queue[str | None] = queue.Queue()
        self.errors: deque[str] = deque(maxlen=12)
        self._finalizer: Any = None

    # ---- the process
    def _start(self) -> None:
        try:
            proc = subprocess.Popen(
                self.words, cwd=self.cwd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                text=True, bufsize=1, encoding="utf-8", errors="replace",
            )
        except OSError as exc:
            raise PlannerError(f"could not start {shlex.join(self.words)!r}: {exc}") from None
        self.proc = proc
        self.lines = queue.Queue()
        self.errors = deque(maxlen=12)
        assert proc.stdout is not None and proc.stderr is not None
        threading.Thread(target=_pump, args=(proc.stdout, self.lines), daemon=True).start()
        threading.Thread(target=_keep_tail, args=(proc.stderr, self.errors), daemon=True).start()
        self._finalizer = weakref.finalize(self, _stop, proc)
        self._send(self.messages.hello(), "start")

    def _crashed(self, where: str) -> PlannerError:
        proc = self.proc
        status = None
        if proc is not None:
            try:
                status = proc.wait(timeout=2.0)
            except subprocess.TimeoutExpired:
                status = None
        self._drop()
        what = "closed its output" if status is None else f"exited with status {status}"
        tail = " | ".join(line for line in list(self.errors)[-4:] if line.strip())
        return PlannerError(f"{where}: the planner {what}" + (f"; its last error output: {tail}" if tail else ""))

    def _drop(self) -> None:
        if self._finalizer is not None:
            self._finalizer()  # stops the process
            self._finalizer = None
        self.proc = None

    def _send(self, message: dict[str, Any], where: str) -> None:
        proc = self.proc
        assert proc is not None and proc.stdin is not None
        try:
            proc.stdin.write(json.dumps(message, separators=(",", ":")) + "\n")
            proc.stdin.flush()
        except (BrokenPipeError, OSError, ValueError):
            raise self._crashed(where) from None

    def _receive(self, where: str) -> str:
        try:
            line = self.lines.get(timeout=self.timeout)
        except queue.Empty:
            self._drop()
            raise PlannerError(f"{where}: the planner sent no answer within {self.timeout:g} s "
                               "(--step-timeout); it was stopped") from None
        if line is None:
            raise self._crashed(where)
        return line

    # ---- the Policy interface
    def reset(self, seed: int | None = None) -> None:
        self.messages.count = 0
        if self.proc is None or self.proc.poll() is not None:
            self._drop()
            self._start()
        self._send({"type": "reset", "seed": seed}, "reset")

    def act(self, observation: Any, info: dict[str, Any]) -> int:
        msg, mask, s = self.messages.step(observation, info)
        where = f"step {msg['step']}"
        if self.proc is None:
            raise PlannerError(f"{where}: the planner is not running (reset was not called)")
        try:
            early = self.lines.get_nowait()
        except queue.Empty:
            early = ""
        if early is None:
            raise self._crashed(where)
        if early:
            self._drop()
            raise PlannerError(f"{where}: the planner wrote {_short(early)} before it was asked (one line per step "
                               "on standard output; write logs to standard error)")
        self._send(msg, where)
        line = self._receive(where)
        try:
            return parse_answer(line, self.game, s, mask, msg["step"], hint=LOGS_HINT)
        except PlannerError:
            self._drop()
            raise

    def episode_end(self, verdict: dict[str, Any]) -> None:
        """Tell the planner the run's verdict (no answer expected)."""
        if self.proc is not None and self.proc.poll() is None:
            try:
                self._send({"type": "end", "verdict": verdict}, "end")
            except PlannerError:
                pass

    def close(self) -> None:
        """Close the planner's input and end the process."""
        self._drop()


def make_command(env: Any, arg: str, step_timeout: float | None = None) -> CommandPlanner:
    """``cmd:COMMAND``: a planner process for ``env`` (started at its first run).

    Raises
    ------
    PolicyError
        If the command cannot be split or its program is not found.
    """
    return CommandPlanner(f"cmd:{arg}", env, arg, step_timeout)


def check_spec(prefix: str, arg: str) -> None:
    """Check a ``python:`` or ``cmd:`` name before anything runs (the module and name
    exist, the program is found).

    Raises
    ------
    PolicyError
        Saying what is missing.
    """
    if prefix == "python":
        resolve(arg)
    elif prefix == "cmd":
        command_words(arg)
