"""Systems under test written outside FlowTest: a Python planner or a planner process.

Two names put your own system wherever FlowTest names one (``flowtest evaluate --sut``,
``flowtest benchmark --sut``, :func:`experiments.evaluation.evaluate`):

* ``python:MODULE:NAME`` — ``NAME`` in the Python module ``MODULE`` (found from the current
  directory, then ``sys.path``, as ``python -m`` finds modules; ``MODULE`` may also be a
  file, ``python:planners/bfs.py:Planner``). ``NAME`` is either

  - a **planner function** ``act(observation, mask) -> action`` (two parameters), or
  - a **factory**: a class, or a function of zero or one parameter, returning a planner:
    an object with ``act(observation, mask) -> action`` (or callable as such) and,
    optionally, ``reset(seed)`` (called before every run) and ``close()``. A factory of
    one parameter receives the test's public description (the ``test`` of the
    protocol's ``hello`` message below).

  **Arguments**: ``python:MODULE:NAME(ARGS)`` calls the factory ``NAME`` with ``ARGS``
  instead, Python literals only (strings, numbers, booleans, ``None``, lists, tuples,
  dicts; keyword arguments too), never evaluated as code:
  ``python:planners.py:Bfs(depth=3)``, ``python:mypkg.policies:load("runs/seed0.pt")``. The
  name with its arguments is the system's name, so a recorded command reruns it as it ran
  (quote it for the shell). ``flowtest benchmark`` also scores batched policies named
  this way (:mod:`agents.batched`).

* ``cmd:COMMAND`` — a process in any language (``cmd:"python3 planner.py"``,
  ``cmd:"awk -f planner.awk"``), started in the current directory, speaking the JSON-lines
  protocol below on its standard input and output; its standard error is kept for the
  report's message if it fails. ``COMMAND`` is split as a shell would split words
  (``shlex``), with no shell features (write ``cmd:"sh -c '...'"`` for those).

The protocol (one JSON object per line; FlowTest writes compact JSON), version 2
----------------------------------------------------------------------------------
FlowTest to the planner:

``{"type": "hello", "protocol": "flowtest-planner", "version": 2, "test": {...}}``
    Once, when the process starts. ``test`` (:func:`flowtest_env.runtime.describe`):
    ``name``, ``kind`` (``static``, ``reactive``, ``mixed``, ``agent``), ``objective`` (the
    system objective, the SUT's own task; never the hidden test objective), ``system`` (the
    transition system as the artifact writes it: ``states``, ``moves``, ``labels``,
    ``layout``, ...; docs/artifact-schema.md; the labels only of the system objective's
    propositions, as the environments show them; the test's static walls apart, in
    ``walls``, and not among ``moves``), ``automaton`` (the system objective's automaton over
    the system's states: ``initial``, ``accepting``, ``next[q][s]``), ``actions`` (the action
    names of a grid: ``N S E W stay``; on graphs ``null``: the names are given per step),
    ``max_steps`` and ``agent`` (whether a test agent moves). That is what the built-in
    systems know (``scripted:replanner`` plans on exactly this).
``{"type": "reset", "seed": S}``
    A run starts (``seed`` is the run's seed, for a planner that draws random numbers).
``{"type": "step", "step": K, "state": ..., "allowed": [...], "to": [...], "mask": [...], "restricted": [...], "agent": ...}``
    Answer it. ``state``: the system's state as in problem-format.md (``[row, col]``,
    ``[[row, col], fuel]`` or a state name); ``allowed``: the names of the actions the
    test allows now (``"N"``, ``"stay"``, on graphs ``"-> NAME"``); ``to``: the state each
    allowed action leads to, in the same order; ``mask``: per action index 1 if allowed;
    ``restricted``: the moves out of ``state`` refused now, ``{"action", "to", "by"}`` with
    ``by`` one of ``wall`` (static, for the whole test), ``door`` (the test closes it now;
    it may open again) and ``agent`` (the test agent stands there); ``agent``: the test
    agent's place (``[row, col]`` or a place name), or ``null``.
``{"type": "end", "verdict": {...}}``
    The run ended (the verdict of ``flowtest evaluate``); no answer.

Version 1 had no ``walls``, ``automaton`` or ``restricted`` (its ``moves`` held the walled
moves too); a version 1 planner works unchanged.

The planner answers every ``step`` with one line: ``{"action": A}``, or ``A`` alone,
where ``A`` is an action index (``0``) or name (``"N"``, ``N``, ``stay``). It must answer
within the step timeout (``--step-timeout``, default :data:`DEFAULT_STEP_TIMEOUT` s, at most
:data:`MAX_STEP_TIMEOUT`; the first answer includes the process's start), and read each
message within it too, and must choose an allowed action. A planner that exits, hangs,
stops reading, answers something that is not an action (a line over
:data:`MAX_ANSWER` bytes is not one) or an action the test does not allow now **fails the
run** (:class:`PlannerError`): the run is reported as the system's failure with what
happened (the exit status and the end of its error output, the step), and every other
system and test still runs. At the end FlowTest closes the planner's standard input; it
should then exit (it is killed, with every process of its group, half a second later).

A planner process runs in a session of its own (:mod:`agents.planner_process`): Ctrl-C at
the terminal reaches FlowTest only, which stops at once and kills the planner's whole
process group, background children included.

A ``python:`` planner receives exactly these ``step`` messages as ``observation`` (a
``dict``; plus ``observation["observation"]``, the Gymnasium environment's observation
array) and ``mask`` as an ``int8`` array; its answer is an index or a name as above. It
runs in a child process forked from FlowTest's (its own session, its prints sent to
standard error), so a planner that loops, sleeps, exits (``sys.exit``) or swallows every
exception (a bare ``except:``) is stopped at the step timeout and fails its run; what it
changes in its own objects stays in that process. Its factory runs there too, within the
step timeout.

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

import ast
import importlib
import importlib.util
import inspect
import json
import os
import pickle
import re
import shlex
import shutil
import signal
import socket
import struct
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from .base import PolicyError
from .planner_process import Running, WireClosed, WireTimeout, WireTooLong, fork_child, frame_bytes, start_command
from .planner_protocol import (
    DEFAULT_STEP_TIMEOUT,
    MAX_ANSWER,
    MAX_STEP_TIMEOUT,
    PROTOCOL,
    PROTOCOL_VERSION,
    Messages,
    PlannerError,
    describe_test,
    parse_answer,
    plain_answer,
    short,
    step_timeout,
)

__all__ = [
    "DEFAULT_STEP_TIMEOUT",
    "MAX_ANSWER",
    "MAX_STEP_TIMEOUT",
    "PREFIXES",
    "PROTOCOL",
    "PROTOCOL_VERSION",
    "CommandPlanner",
    "PlannerError",
    "PythonPlanner",
    "check_spec",
    "command_words",
    "describe_test",
    "is_planner_function",
    "make_command",
    "make_python",
    "parse_answer",
    "planner_policy",
    "python_call",
    "resolve",
    "spec_of",
    "split_call",
]

PREFIXES = ("python", "cmd")
"""The name prefixes of systems from outside FlowTest."""

CLOSE_GRACE = 0.5
"""Seconds a planner is given to exit after its input is closed at the end, before its
process group is killed (none when a Ctrl-C is on its way)."""


def _interrupted() -> bool:
    """Whether a Ctrl-C (or SIGTERM, which takes its path) is unwinding the caller now."""
    return isinstance(sys.exc_info()[1], KeyboardInterrupt)


def _ended(status: int | None) -> str:
    """How a planner process ended, for a message."""
    if status is None:
        return "closed its output"
    if status < 0:
        try:
            return f"was ended by signal {signal.Signals(-status).name}"
        except ValueError:
            return f"was ended by signal {-status}"
    return f"exited with status {status}"


# --------------------------------------------------------------------------- python:


def _import(module: str) -> Any:
    """Import ``module`` as ``python -m`` would (the current directory first), or load a
    ``.py`` file.

    Raises
    ------
    PolicyError
        If it is missing, or raises (``sys.exit()`` included) while being imported.
    """
    cwd = os.getcwd()
    if module.endswith(".py"):
        path = Path(module)
        if not path.is_file():
            raise PolicyError(f"no Python file {module!r} (from {cwd})")
        name = path.stem
        taken = sys.modules.get(name)
        if taken is not None and getattr(taken, "__file__", None) != str(path.resolve()):
            name = f"_flowtest_file_{name}_{abs(hash(str(path.resolve())))}"  # another module has its name
        spec = importlib.util.spec_from_file_location(name, path.resolve())
        if spec is None or spec.loader is None:
            raise PolicyError(f"cannot load {module!r} as a Python module")
        mod = importlib.util.module_from_spec(spec)
        sys.modules[name] = mod  # while it runs, as an import does (a dataclass there looks its module up)
        try:
            spec.loader.exec_module(mod)
        except (Exception, SystemExit) as exc:  # the user's file is broken, or raises while it runs
            sys.modules.pop(name, None)
            raise PolicyError(f"{module!r} could not be loaded: it {_did(exc)}") from None
        return mod
    if cwd not in sys.path and "" not in sys.path:
        sys.path.insert(0, cwd)
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        if exc.name and (module == exc.name or module.startswith(exc.name + ".")):
            raise PolicyError(f"no Python module {module!r} (looked in {cwd} and sys.path)") from None
        raise PolicyError(f"module {module!r} could not be imported: {type(exc).__name__}: {exc}") from None
    except SystemExit as exc:
        raise PolicyError(f"module {module!r} {_did(exc)} while being imported") from None
    except Exception as exc:  # the user's module raised while being imported
        raise PolicyError(f"module {module!r} raised while being imported: {_raised(exc)}") from None


def _did(exc: BaseException) -> str:
    """What a planner did, by the exception it ended with: ``raised ValueError: text``,
    ``called sys.exit(3)``."""
    return f"called sys.exit({short(exc.code)})" if isinstance(exc, SystemExit) else f"raised {_raised(exc)}"


def _raised(exc: BaseException) -> str:
    """What an exception says: ``ValueError: text`` (its type alone when it says nothing)."""
    try:
        text = str(exc)
    except Exception:  # an exception whose str fails
        text = ""
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


_CALL_TARGET = re.compile(r"^([^()\"']+:[A-Za-z_][A-Za-z0-9_.]*)\((.*)\)$", re.DOTALL)
"""``MODULE:NAME(ARGS)``: the target and the text between the parentheses."""


def split_call(spec: str) -> tuple[str, tuple[Any, ...], dict[str, Any]] | None:
    """``MODULE:NAME(ARGS)`` as ``("MODULE:NAME", args, kwargs)`` (``ARGS`` Python literals,
    read by :func:`ast.literal_eval`, never run); ``None`` for a spec without arguments.

    Example::

        >>> split_call('mypkg.policies:load("runs/seed0.pt", device="cpu")')
        ('mypkg.policies:load', ('runs/seed0.pt',), {'device': 'cpu'})
        >>> split_call("planners.py:Bfs") is None
        True

    Raises
    ------
    PolicyError
        If the arguments are not Python literals (a name, a call, ``*args``).
    """
    m = _CALL_TARGET.match(spec.strip())
    if m is None:
        return None
    target, text = m.group(1), m.group(2)
    try:
        call = ast.parse(f"f({text})", mode="eval").body
    except (SyntaxError, ValueError, RecursionError):
        raise PolicyError(f"python:{target}(...): the arguments {short(text)} are not Python literals separated by commas") from None
    assert isinstance(call, ast.Call)
    try:
        if any(isinstance(a, ast.Starred) for a in call.args) or any(k.arg is None for k in call.keywords):
            raise ValueError("*args or **kwargs")
        args = tuple(ast.literal_eval(a) for a in call.args)
        kwargs = {str(k.arg): ast.literal_eval(k.value) for k in call.keywords}
    except (ValueError, TypeError, RecursionError):
        raise PolicyError(
            f"python:{target}(...): the arguments must be Python literals (strings, numbers, True/False/None, lists, tuples, dicts), not {short(text)}"
        ) from None
    return target, args, kwargs


def python_call(spec: str) -> tuple[Any, tuple[Any, ...], dict[str, Any]]:
    """The object ``MODULE:NAME`` names and the arguments of ``MODULE:NAME(ARGS)`` (none
    without them): what ``python:SPEC`` calls.

    Raises
    ------
    PolicyError
        On malformed arguments, a missing module or name.
    """
    call = split_call(spec)
    if call is None:
        return resolve(spec), (), {}
    target, args, kwargs = call
    return resolve(target), args, kwargs


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
        p.kind in (inspect.Parameter.POSITIONAL_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD) for p in params
    )


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


def _serve_planner(sock: socket.socket, build: Any) -> None:
    """The child's side of a ``python:`` planner (:func:`agents.planner_process.fork_child`):
    build the planner, say ``ready`` (or why not), then answer each request (``reset``,
    ``act``, ``close``) with ``("ok", value)`` or ``("raised", what)`` until the parent
    closes the socket. Whatever the planner raises, ``SystemExit`` and ``KeyboardInterrupt``
    included, is an answer: its run fails, the evaluation goes on."""
    sock.setblocking(True)
    reader = sock.makefile("rb")

    def send(value: Any) -> None:
        sock.sendall(frame_bytes(value))

    try:
        planner, act = build()
    except PolicyError as exc:
        send(("failed", str(exc)))
        return
    except BaseException as exc:  # the planner's factory, whatever it raises
        send(("failed", f"the factory {_did(exc)}"))
        return
    reset = getattr(planner, "reset", None)
    reset = reset if callable(reset) and reset is not act else None
    send(("ready", None))
    while True:
        head = reader.read(4)
        if len(head) < 4:
            return
        request = pickle.loads(reader.read(struct.unpack("!I", head)[0]))
        try:
            if request[0] == "act":
                message, observation, mask = request[1], _unpack(request[2]), _unpack(request[3])
                message["observation"] = observation
                send(("ok", plain_answer(act(message, mask))))
                continue
            if request[0] == "reset" and reset is not None:
                reset(request[1])
            elif request[0] == "close":
                close = getattr(planner, "close", None)
                if callable(close):
                    close()
            send(("ok", None))
        except BaseException as exc:  # the planner's own failure, reported as its run's
            send(("raised", _did(exc)))


def _pack(value: Any) -> Any:
    """An array as its dtype, shape and bytes (pickled several times faster than the array
    itself); anything else as it is."""
    if type(value) is np.ndarray:
        return ("ndarray", value.dtype.str, value.shape, value.tobytes())
    return value


def _unpack(value: Any) -> Any:
    """:func:`_pack` undone: a fresh, writable array."""
    if isinstance(value, tuple) and len(value) == 4 and value[0] == "ndarray":
        return np.frombuffer(value[3], dtype=np.dtype(value[1])).reshape(value[2]).copy()
    return value


class PythonPlanner:
    """A Python planner as a FlowTest :class:`~agents.base.Policy` (see the module docstring),
    played in a forked child process that the step timeout stops.

    ``target`` is a planner function, a factory, or (``built``, from :func:`planner_policy`)
    a planner object itself. The factory runs at once, in the child.

    Raises
    ------
    PolicyError
        If the step timeout is out of range, or the factory fails (raises, exits, returns no
        planner, or takes longer than the step timeout).
    """

    def __init__(self, name: str, env: Any, target: Any, built: bool = False, step_timeout: float | None = None) -> None:
        self.name = name
        self.timeout = _timeout(step_timeout)
        self.messages = Messages(env)
        self.game = self.messages.game
        self.target, self.built = target, built
        self.running: Running | None = None
        problem = self._start()
        if problem is not None:
            raise PolicyError(problem)

    def _build(self) -> tuple[Any, Any]:
        """(in the child) The planner and its ``act``."""
        if self.built or is_planner_function(self.target):
            planner = self.target
        else:
            planner = self.target(self.messages.test) if _accepts_one(self.target) else self.target()
        act = getattr(planner, "act", None)
        act = act if callable(act) else planner
        if not callable(act):
            raise PolicyError(f"the factory returned a {type(planner).__name__} with no act(observation, mask)")
        return planner, act

    def _start(self) -> str | None:
        """Fork the child and build the planner there; ``None``, or why it did not start."""
        self.running = fork_child(lambda theirs: _serve_planner(theirs, self._build), 1 << 20)
        try:
            kind, value = self.running.wire.frame(time.monotonic() + self.timeout)
        except WireTimeout:
            self._drop()
            return f"the factory did not return within {self.timeout:g} s (--step-timeout)"
        except WireClosed:
            return f"the planner's process {_ended(self._drop(wait=1.0))} before it was ready"
        except BaseException:
            self._drop()
            raise
        if kind != "ready":
            self._drop()
            return str(value)
        return None

    def _drop(self, grace: float = 0.0, wait: float = 0.0) -> int | None:
        """End the child (its whole process group); its exit status."""
        running, self.running = self.running, None
        return running.end(grace, wait) if running is not None else None

    def _call(self, request: tuple[Any, ...], where: str, late: str) -> Any:
        """Send ``request`` to the child and return its answer's value, within the step timeout.

        Raises
        ------
        PlannerError
            If the planner did not answer in time (``late``), raised, or its process ended.
        """
        if self.running is None:
            problem = self._start()
            if problem is not None:
                raise PlannerError(f"{where}: {problem}")
        assert self.running is not None
        deadline = time.monotonic() + self.timeout
        try:
            self.running.wire.send(frame_bytes(request), deadline)
            kind, value = self.running.wire.frame(deadline)
        except WireTimeout:
            self._drop()
            raise PlannerError(f"{where}: {late} within {self.timeout:g} s (--step-timeout); it was stopped") from None
        except (WireClosed, WireTooLong):
            raise PlannerError(f"{where}: the planner's process {_ended(self._drop(wait=1.0))}") from None
        except BaseException:
            self._drop()
            raise
        if kind != "ok":
            self._drop()
            raise PlannerError(f"{where}: {value}")
        return value

    def reset(self, seed: int | None = None) -> None:
        """A run starts: the planner's ``reset(seed)``, if it has one."""
        self.messages.count = 0
        self._call(("reset", seed), "reset", "the planner did not return")

    def act(self, observation: Any, info: dict[str, Any]) -> int:
        """The planner's answer to this step, as an allowed action index."""
        msg, mask, s = self.messages.step(observation, info)
        answer = self._call(("act", msg, _pack(observation), _pack(mask)), f"step {msg['step']}", "the planner gave no answer")
        try:
            return parse_answer(answer, self.game, s, mask, msg["step"])
        except PlannerError:
            self._drop()
            raise

    def close(self) -> None:
        """The planner's ``close()``, then the end of its process."""
        if self.running is not None and not _interrupted():
            deadline = time.monotonic() + min(self.timeout, 1.0)
            try:
                self.running.wire.send(frame_bytes(("close",)), deadline)
                self.running.wire.frame(deadline)
            except (WireTimeout, WireClosed, WireTooLong):
                pass
            except BaseException:
                self._drop()
                raise
        self._drop()


def _timeout(seconds: float | None) -> float:
    return step_timeout(seconds)


def make_python(env: Any, arg: str, step_timeout: float | None = None) -> PythonPlanner:
    """``python:MODULE:NAME``: the planner ``NAME`` of ``MODULE`` for ``env``;
    ``python:MODULE:NAME(ARGS)``: the planner the factory ``NAME`` returns when called with
    ``ARGS`` (:func:`split_call`), in the planner's child process.

    Raises
    ------
    PolicyError
        If the module or the name is missing, the arguments are not literals, or the factory fails.
    """
    obj, args, kwargs = python_call(arg)
    if args or kwargs or split_call(arg) is not None:

        def factory() -> Any:  # called with exactly the given arguments (not the test's description)
            return obj(*args, **kwargs)

        factory.__qualname__ = getattr(obj, "__qualname__", "factory")
        return PythonPlanner(f"python:{arg}", env, factory, step_timeout=step_timeout)
    return PythonPlanner(f"python:{arg}", env, obj, step_timeout=step_timeout)


def planner_policy(obj: Any, env: Any, name: str | None = None, step_timeout: float | None = None) -> PythonPlanner:
    """A planner given as a Python object (a function, a factory, or a planner object with
    ``act(observation, mask)``) as a :class:`~agents.base.Policy` for ``env``; named
    ``name``, else by :func:`spec_of` where it can be, else by its type. It runs in a
    child process, and each call of its ``act`` and ``reset`` may take ``step_timeout``
    seconds (default :data:`DEFAULT_STEP_TIMEOUT`).

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
    >>> policy.close()
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
        raise PolicyError('cmd: needs a command, e.g. cmd:"python3 planner.py"')
    prog = words[0]
    if os.sep in prog or (os.altsep and os.altsep in prog):
        if not Path(prog).is_file():
            raise PolicyError(f"no program {prog!r} (from {os.getcwd()})")
        if not os.access(prog, os.X_OK):
            raise PolicyError(f"{prog!r} is not executable (chmod +x, or run it through its interpreter)")
    elif shutil.which(prog) is None:
        raise PolicyError(f"command {prog!r} not found on PATH")
    return words


LOGS_HINT = "; a planner process answers one line per step on standard output and writes its logs to standard error"
"""Said after an answer line of a process that is not an action: most often a log line."""


class CommandPlanner:
    """A planner process speaking the JSON-lines protocol, as a FlowTest
    :class:`~agents.base.Policy` (see the module docstring). The process starts at the
    first run and serves every run of this policy; after a failure the next run starts a
    fresh one. It is ended by :meth:`close` (or when the policy is collected)."""

    def __init__(self, name: str, env: Any, arg: str, step_timeout: float | None = None) -> None:
        self.name = name
        self.words = command_words(arg)
        self.cwd = os.getcwd()
        self.timeout = _timeout(step_timeout)
        self.messages = Messages(env)
        self.game = self.messages.game
        self.running: Running | None = None
        self._unread: str | None = None  # why the next run fails: the last run's end was not read

    # ---- the process
    def _start(self) -> None:
        try:
            self.running = start_command(self.words, self.cwd, MAX_ANSWER)
        except OSError as exc:
            raise PlannerError(f"could not start {shlex.join(self.words)!r}: {exc}") from None
        self._send(self.messages.hello(), "start", time.monotonic() + self.timeout)

    def _drop(self, grace: float = 0.0, wait: float = 0.0) -> int | None:
        """End the process (its whole group); its exit status."""
        running, self.running = self.running, None
        return running.end(grace, wait) if running is not None else None

    def _crashed(self, where: str) -> PlannerError:
        status, tail = None, ""
        if self.running is not None:
            status = self.running.session.wait_exit(1.0)
            tail = self.running.wire.error_tail()
        self._drop()
        return PlannerError(f"{where}: the planner {_ended(status)}" + (f"; its last error output: {tail}" if tail else ""))

    def _send(self, message: dict[str, Any], where: str, deadline: float) -> None:
        assert self.running is not None
        data = (json.dumps(message, separators=(",", ":"), allow_nan=False) + "\n").encode()
        try:
            self.running.wire.send(data, deadline)
        except WireTimeout:
            self._drop()
            raise PlannerError(f"{where}: the planner did not read its input within {self.timeout:g} s (--step-timeout); it was stopped") from None
        except WireClosed:
            raise self._crashed(where) from None
        except BaseException:
            self._drop()
            raise

    def _receive(self, where: str, deadline: float) -> bytes:
        assert self.running is not None
        try:
            return self.running.wire.line(deadline)
        except WireTimeout:
            self._drop()
            raise PlannerError(f"{where}: the planner sent no answer within {self.timeout:g} s (--step-timeout); it was stopped") from None
        except WireClosed:
            raise self._crashed(where) from None
        except WireTooLong:
            self._drop()
            raise PlannerError(f"{where}: the planner answered a line longer than {MAX_ANSWER} bytes, which is not an action" + LOGS_HINT) from None
        except BaseException:
            self._drop()
            raise

    # ---- the Policy interface
    def reset(self, seed: int | None = None) -> None:
        """A run starts: the process (started if it is not running) gets ``reset``."""
        self.messages.count = 0
        if self._unread is not None:
            why, self._unread = self._unread, None
            self._drop()
            raise PlannerError(why)
        if self.running is None or self.running.session.exit_status() is not None:
            self._drop()
            self._start()
        self._send({"type": "reset", "seed": seed}, "reset", time.monotonic() + self.timeout)

    def act(self, observation: Any, info: dict[str, Any]) -> int:
        """Send this step and read the planner's answer, within the step timeout."""
        msg, mask, s = self.messages.step(observation, info)
        where = f"step {msg['step']}"
        if self.running is None:
            raise PlannerError(f"{where}: the planner is not running (reset was not called)")
        deadline = time.monotonic() + self.timeout
        try:
            early, ended = self.running.wire.unasked()
        except BaseException:
            self._drop()
            raise
        if early:
            self._drop()
            first = early.decode("utf-8", "replace").split("\n")[0]
            raise PlannerError(
                f"{where}: the planner wrote {short(first)} before it was asked (one line per step on standard output; write logs to standard error)"
            )
        if ended:
            raise self._crashed(where)
        self._send(msg, where, deadline)
        line = self._receive(where, deadline)
        assert self.running is not None  # _receive ends the process only by raising
        if self.running.wire.unread_input():
            self._drop()
            raise PlannerError(
                f"{where}: the planner answered {short(line.decode('utf-8', 'replace'))} without reading this step (its input was "
                "left unread): one line per step on standard output, after reading the step; write logs to standard error"
            )
        try:
            return parse_answer(line, self.game, s, mask, msg["step"], hint=LOGS_HINT)
        except PlannerError:
            self._drop()
            raise

    def episode_end(self, verdict: dict[str, Any]) -> None:
        """Tell the planner the run's verdict (no answer expected). A planner that does not
        read it within the step timeout fails the next run (it has stopped reading)."""
        if self.running is None or self.running.session.exit_status() is not None:
            return
        data = (json.dumps({"type": "end", "verdict": verdict}, separators=(",", ":")) + "\n").encode()
        try:
            self.running.wire.send(data, time.monotonic() + self.timeout)
        except WireTimeout:
            self._drop()
            self._unread = f"reset: the planner did not read the end of the last run within {self.timeout:g} s (--step-timeout); it was stopped"
        except WireClosed:
            self._drop()
        except BaseException:
            self._drop()
            raise

    def close(self) -> None:
        """Close the planner's input and end its process group (at once on Ctrl-C, else after
        :data:`CLOSE_GRACE` seconds at most)."""
        self._drop(grace=0.0 if _interrupted() else CLOSE_GRACE)


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
        python_call(arg)
    elif prefix == "cmd":
        command_words(arg)
