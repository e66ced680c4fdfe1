"""``flowtest serve ARTIFACT``: a synthesized test as a runtime for another process, over
JSON lines (standard input and output, or a localhost socket with ``--port``).

Each request is one JSON object on one line, each answer one line of JSON (always valid
JSON: ``NaN`` and ``Infinity`` are refused on the way in); the protocol (docs/runtime.md,
version :data:`VERSION`) is :class:`flowtest_env.runtime.TestRuntime`'s API:

==============================================  =========================================
request                                         answer
==============================================  =========================================
``{"op": "describe"}``                          ``{"ok": true, "protocol": ..., "version": 2, "test": {...}}``
``{"op": "reset"}``                             ``{"ok": true, "status": {...}}``
``{"op": "step", "state": [1, 2]}``             ``{"ok": true, "status": {...}}``
``{"op": "step", "action": "N"}``               ``{"ok": true, "status": {...}}``
``{"op": "status"}``                            ``{"ok": true, "status": {...}}``
``{"op": "quit"}``                              ``{"ok": true}``, then the session ends
``{"op": "shutdown"}``                          ``{"ok": true}``, then the server ends
==============================================  =========================================

A request that cannot be honoured (not JSON, an unknown ``op``, a state the system cannot
have entered) is answered ``{"ok": false, "code": "...", "error": "..."}`` (the codes:
:data:`ERRORS`) and the session goes on; an answer repeats the request's ``id`` (a string,
a number or ``null``) if it has one. A status names the histories neutrally (``q3``)
unless ``--reveal``: their descriptions give the hidden test objective away.

On a socket (``--port N``, bound to 127.0.0.1 only; ``--port 0`` picks a free port) each
connection is its own session with its own run, served at the same time as the others, at
most ``--max-clients`` at once (one more is answered ``busy`` and closed); a connection
that sends no request for ``--idle-timeout`` seconds is answered ``idle`` and closed.

    $ printf '%s\\n' '{"op":"reset"}' '{"op":"step","action":"E"}' | flowtest serve small-reactive
"""

from __future__ import annotations

import argparse
import io
import json
import socketserver
import sys
import threading
from collections.abc import Callable
from typing import IO, Any

from synthesis.model.errors import ProblemError

from .arguments import int_between, seconds_at_most
from .command import Command
from .exits import EXIT_OK

PROTOCOL, VERSION = "flowtest-serve", 2
"""The protocol's name and version. 2: error codes, the verdict's ``reason``, ``door``
(was ``test``) as the cause of a restriction, neutral history names, the static walls apart
from the moves in ``describe``, ``shutdown``; sessions served at the same time."""

MAX_REQUEST = 1 << 20
"""Longest request line read (bytes); a longer one is refused and the session ends."""

IDLE_TIMEOUT, MAX_IDLE_TIMEOUT = 300.0, 86_400.0
"""Seconds a socket session may wait for its next request (default, and the largest
``--idle-timeout``)."""

MAX_CLIENTS = 16
"""Sessions served at once on a socket (``--max-clients``' default)."""

MAX_ID = 256
"""Longest request ``id`` string echoed."""

OPS = ("describe", "reset", "step", "status", "quit", "shutdown")

ERRORS = {
    "not_json": "the line is not one JSON value (NaN and Infinity are not JSON)",
    "not_an_object": "the request is not a JSON object",
    "unknown_op": "no such op",
    "bad_id": "the id is not a string (at most 256 characters), a number or null",
    "too_long": "the request line is longer than 1 MiB; the session ends",
    "busy": "every session is taken (--max-clients); the connection is closed",
    "idle": "no request within --idle-timeout; the connection is closed",
}
"""The error codes of the server itself, and what each means; a step's refusals add
:data:`flowtest_env.runtime.REFUSALS`."""


def _refused(code: str, error: str, ident: dict[str, Any] | None = None) -> dict[str, Any]:
    return {"ok": False, **(ident or {}), "code": code, "error": error}


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not JSON")


def _ident(request: dict[str, Any]) -> dict[str, Any] | None:
    """``{"id": ...}`` to echo (empty without one), or ``None`` for an id that is no id."""
    if "id" not in request:
        return {}
    ident = request["id"]
    if ident is None or (isinstance(ident, (int, float)) and not isinstance(ident, bool)):
        return {"id": ident}
    if isinstance(ident, str) and len(ident) <= MAX_ID:
        return {"id": ident}
    return None


def answer(runtime: Any, request: Any) -> tuple[dict[str, Any], str]:
    """The answer to one request, and what comes next: ``"more"`` (the session goes on),
    ``"quit"`` (it ends) or ``"shutdown"`` (the server ends)."""
    from flowtest_env.runtime import RuntimeRefused

    if not isinstance(request, dict):
        return _refused("not_an_object", 'a request is a JSON object, e.g. {"op": "reset"}'), "more"
    ident = _ident(request)
    if ident is None:
        return _refused("bad_id", "an id is a string (at most 256 characters), a number or null"), "more"
    op = request.get("op")
    try:
        if op == "describe":
            return {"ok": True, **ident, "protocol": PROTOCOL, "version": VERSION, "test": runtime.describe()}, "more"
        if op == "reset":
            return {"ok": True, **ident, "status": runtime.reset()}, "more"
        if op == "status":
            return {"ok": True, **ident, "status": runtime.status()}, "more"
        if op == "step":
            extra = set(request) - {"op", "id", "state", "action"}
            if extra:
                raise RuntimeRefused(f"unknown field(s) of a step: {', '.join(sorted(map(str, extra)))[:200]}", "bad_request")
            return {"ok": True, **ident, "status": runtime.step(request.get("state"), request.get("action"))}, "more"
        if op in ("quit", "shutdown"):
            return {"ok": True, **ident}, str(op)
    except RuntimeRefused as exc:
        return _refused(exc.code, str(exc), ident), "more"
    shown = json.dumps(op)[:40]
    return _refused("unknown_op", f"unknown op {shown}; expected one of {', '.join(OPS)}", ident), "more"


def encode(reply: dict[str, Any]) -> str:
    """One answer line: compact JSON, never ``NaN`` (a value that is not JSON is a bug,
    answered as such instead of sent)."""
    try:
        return json.dumps(reply, separators=(",", ":"), allow_nan=False) + "\n"
    except (ValueError, TypeError, RecursionError) as exc:  # pragma: no cover - every value sent is checked JSON
        return json.dumps(_refused("internal", f"an answer that is not JSON (a FlowTest bug): {exc}")) + "\n"


def serve_lines(runtime: Any, read_line: Callable[[], str], write: Callable[[str], None]) -> str:
    """Answer requests read by ``read_line`` (``""`` at the end) until the end (``"end"``),
    ``quit`` or ``shutdown`` (returned)."""
    while True:
        line = read_line()
        if not line:
            return "end"
        if not line.endswith("\n") and len(line) >= MAX_REQUEST:
            write(encode(_refused("too_long", f"request longer than {MAX_REQUEST} bytes")))
            return "end"
        if not line.strip():
            continue
        try:
            request = json.loads(line, parse_constant=_no_constant)
        except (ValueError, RecursionError):
            reply, then = _refused("not_json", "not a JSON object on one line (NaN and Infinity are not JSON)"), "more"
        else:
            reply, then = answer(runtime, request)
        write(encode(reply))
        if then != "more":
            return then


def serve_stream(runtime: Any, inp: IO[str], out: IO[str]) -> None:
    """Serve one session over text streams (standard input and output); ``quit`` and
    ``shutdown`` both end it."""

    def write(text: str) -> None:
        out.write(text)
        out.flush()

    serve_lines(runtime, lambda: inp.readline(MAX_REQUEST), write)


class SessionServer(socketserver.ThreadingTCPServer):
    """A TCP server on 127.0.0.1 that serves each connection in a thread of its own, at most
    ``max_clients`` at once (one more is answered ``busy`` and closed at once)."""

    allow_reuse_address = True
    daemon_threads = True
    block_on_close = False

    def __init__(self, port: int, handler: type[socketserver.BaseRequestHandler], max_clients: int) -> None:
        self.max_clients = max_clients
        self.open_sessions = 0
        self._count = threading.Lock()
        super().__init__(("127.0.0.1", port), handler)

    def process_request(self, request: Any, client_address: Any) -> None:
        with self._count:
            full = self.open_sessions >= self.max_clients
            if not full:
                self.open_sessions += 1
        if full:
            try:
                request.settimeout(1.0)
                request.sendall(encode(_refused("busy", f"every session is taken ({self.max_clients}, --max-clients); try again later")).encode())
            except OSError:
                pass
            self.shutdown_request(request)
            return
        try:
            super().process_request(request, client_address)
        except BaseException:  # no thread for it: the place is free again
            self._release()
            self.shutdown_request(request)
            raise

    def process_request_thread(self, request: Any, client_address: Any) -> None:
        try:
            super().process_request_thread(request, client_address)
        finally:
            self._release()

    def _release(self) -> None:
        with self._count:
            self.open_sessions -= 1


def make_server(
    artifact: Any, port: int, max_steps: int | None = None, reveal: bool = False, idle_timeout: float = IDLE_TIMEOUT, max_clients: int = MAX_CLIENTS
) -> SessionServer:
    """A TCP server on 127.0.0.1:``port`` (0: a free port); each connection a session with
    its own runtime of ``artifact``, served at the same time as the others (see the module
    docstring); ``shutdown`` from any session ends it."""
    from flowtest_env.runtime import TestRuntime

    class Session(socketserver.StreamRequestHandler):
        timeout = idle_timeout  # the socket's timeout: reads and writes alike

        def handle(self) -> None:
            runtime = TestRuntime(artifact, max_steps, reveal)

            def read_line() -> str:
                return self.rfile.readline(MAX_REQUEST).decode("utf-8", "replace")

            def write(text: str) -> None:
                self.wfile.write(text.encode("utf-8"))
                self.wfile.flush()

            try:
                then = serve_lines(runtime, read_line, write)
            except TimeoutError:
                try:
                    write(encode(_refused("idle", f"no request within {idle_timeout:g} s (--idle-timeout); the connection is closed")))
                except OSError:
                    pass
                return
            except OSError:
                return  # the client went away
            if then == "shutdown":
                threading.Thread(target=self.server.shutdown, daemon=True).start()

    return SessionServer(port, Session, max_clients)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Declare ``flowtest serve``'s arguments."""
    p.add_argument("test", metavar="ARTIFACT", help="the test: an artifact file (flowtest synthesize --out), a built-in name or a problem file")
    p.add_argument(
        "--port",
        type=int_between(0, 65535, "a port"),
        default=None,
        help="serve on 127.0.0.1:PORT instead of standard input and output (0: a free port, printed)",
    )
    p.add_argument("--max-steps", type=int_between(1, 10**9, "a step budget"), default=None, help="the step budget of a run (default: the environment's)")
    p.add_argument("--reveal", action="store_true", help="name the histories by what the test saw (gives the hidden test objective away; default: q0, q1, ...)")
    p.add_argument(
        "--idle-timeout",
        type=seconds_at_most(MAX_IDLE_TIMEOUT),
        default=IDLE_TIMEOUT,
        metavar="SECONDS",
        help=f"close a socket session that sends no request for this long (default {IDLE_TIMEOUT:g}, at most {MAX_IDLE_TIMEOUT:g})",
    )
    p.add_argument(
        "--max-clients",
        type=int_between(1, 1024, "a number of sessions"),
        default=MAX_CLIENTS,
        help=f"sessions served at once on a socket; one more is answered busy (default {MAX_CLIENTS})",
    )


def run(args: argparse.Namespace) -> int:
    """Serve the test until the input ends (``quit``, ``shutdown``), or, on a socket,
    until ``shutdown`` or Ctrl-C."""
    from flowtest_env.runtime import TestRuntime
    from flowtest_env.sources import load_test

    artifact = load_test(args.test)
    if args.port is None:
        # bytes that are not UTF-8 become U+FFFD (a request that is then answered with an error), not a crash
        inp = io.TextIOWrapper(sys.stdin.buffer, encoding="utf-8", errors="replace") if hasattr(sys.stdin, "buffer") else sys.stdin
        serve_stream(TestRuntime(artifact, args.max_steps, args.reveal), inp, sys.stdout)
        return EXIT_OK
    try:
        server = make_server(artifact, args.port, args.max_steps, args.reveal, args.idle_timeout, args.max_clients)
    except OSError as exc:
        raise ProblemError(f"--port {args.port}: cannot listen on 127.0.0.1:{args.port} ({exc.strerror or exc})") from None
    with server:
        port = int(server.server_address[1])
        sys.stderr.write(f"flowtest: serving {artifact.name} on 127.0.0.1:{port}\n")
        sys.stderr.flush()
        server.serve_forever(poll_interval=0.2)
    return EXIT_OK


COMMAND = Command("serve", "run a synthesized test as a runtime for another process, over JSON lines", add_arguments, run)
