"""``flowtest serve ARTIFACT``: a synthesized test as a runtime for another process, over
JSON lines (standard input and output, or a localhost socket with ``--port``).

Each request is one JSON object on one line, each answer one line; the protocol
(docs/runtime.md) is :class:`flowtest_env.runtime.TestRuntime`'s API:

==============================================  =========================================
request                                         answer
==============================================  =========================================
``{"op": "describe"}``                          ``{"ok": true, "test": {...}}``
``{"op": "reset"}``                             ``{"ok": true, "status": {...}}``
``{"op": "step", "state": [1, 2]}``             ``{"ok": true, "status": {...}}``
``{"op": "step", "action": "N"}``               ``{"ok": true, "status": {...}}``
``{"op": "status"}``                            ``{"ok": true, "status": {...}}``
``{"op": "quit"}``                              ``{"ok": true}``, then the session ends
==============================================  =========================================

A request that cannot be honoured (not JSON, an unknown ``op``, a state the system cannot
have entered) is answered ``{"ok": false, "error": "..."}`` and the session goes on; an
answer repeats the request's ``id`` if it has one. On a socket (``--port N``, bound to
127.0.0.1 only; ``--port 0`` picks a free port) each connection is one session with its own
run, served in turn.

    $ printf '%s\\n' '{"op":"reset"}' '{"op":"step","action":"E"}' | flowtest serve small-reactive
"""

from __future__ import annotations

import argparse
import io
import json
import socketserver
import sys
from collections.abc import Callable
from typing import IO, Any

from synthesis.model.errors import ProblemError

from .arguments import int_between, nonnegative_int
from .command import Command
from .exits import EXIT_OK

MAX_REQUEST = 1 << 20
"""Longest request line read (bytes); a longer one is refused and the session ends."""

OPS = ("describe", "reset", "step", "status", "quit")


def answer(runtime: Any, request: Any) -> tuple[dict[str, Any], bool]:
    """The answer to one request and whether the session goes on."""
    from flowtest_env.runtime import RuntimeRefused

    if not isinstance(request, dict):
        return {"ok": False, "error": "a request is a JSON object, e.g. {\"op\": \"reset\"}"}, True
    ident = {"id": request["id"]} if "id" in request else {}
    op = request.get("op")
    try:
        if op == "describe":
            return {"ok": True, **ident, "test": runtime.describe()}, True
        if op == "reset":
            return {"ok": True, **ident, "status": runtime.reset()}, True
        if op == "status":
            return {"ok": True, **ident, "status": runtime.status()}, True
        if op == "step":
            extra = set(request) - {"op", "id", "state", "action"}
            if extra:
                raise RuntimeRefused(f"unknown field(s) of a step: {', '.join(sorted(extra))}")
            return {"ok": True, **ident, "status": runtime.step(request.get("state"), request.get("action"))}, True
        if op == "quit":
            return {"ok": True, **ident}, False
    except RuntimeRefused as exc:
        return {"ok": False, **ident, "error": str(exc)}, True
    shown = json.dumps(op)[:40]
    return {"ok": False, **ident, "error": f"unknown op {shown}; expected one of {', '.join(OPS)}"}, True


def serve_lines(runtime: Any, read_line: Callable[[], str], write: Callable[[str], None]) -> None:
    """Answer requests read by ``read_line`` (``""`` at the end) until the end or ``quit``."""
    while True:
        line = read_line()
        if not line:
            return
        if not line.endswith("\n") and len(line) >= MAX_REQUEST:
            write(json.dumps({"ok": False, "error": f"request longer than {MAX_REQUEST} bytes"}, separators=(",", ":")) + "\n")
            return
        if not line.strip():
            continue
        try:
            request = json.loads(line)
        except (ValueError, RecursionError):
            reply: dict[str, Any] = {"ok": False, "error": "not a JSON object on one line"}
            go_on = True
        else:
            reply, go_on = answer(runtime, request)
        write(json.dumps(reply, separators=(",", ":")) + "\n")
        if not go_on:
            return


def serve_stream(runtime: Any, inp: IO[str], out: IO[str]) -> None:
    """Serve one session over text streams (standard input and output)."""

    def write(text: str) -> None:
        out.write(text)
        out.flush()

    serve_lines(runtime, lambda: inp.readline(MAX_REQUEST), write)


def make_server(artifact: Any, port: int, max_steps: int | None = None) -> socketserver.TCPServer:
    """A TCP server on 127.0.0.1:``port`` (0: a free port); each connection a session
    with its own runtime of ``artifact``, served in turn."""
    from flowtest_env.runtime import TestRuntime

    class Session(socketserver.StreamRequestHandler):
        def handle(self) -> None:
            runtime = TestRuntime(artifact, max_steps)

            def read_line() -> str:
                return self.rfile.readline(MAX_REQUEST).decode("utf-8", "replace")

            def write(text: str) -> None:
                self.wfile.write(text.encode("utf-8"))
                self.wfile.flush()

            try:
                serve_lines(runtime, read_line, write)
            except (ConnectionError, OSError):
                pass  # the client went away

    class Server(socketserver.TCPServer):
        allow_reuse_address = True

    return Server(("127.0.0.1", port), Session)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Declare ``flowtest serve``'s arguments."""
    p.add_argument("test", metavar="ARTIFACT",
                   help="the test: an artifact file (flowtest synthesize --out), a built-in name or a problem file")
    p.add_argument("--port", type=int_between(0, 65535, "a port"), default=None,
                   help="serve on 127.0.0.1:PORT instead of standard input and output (0: a free port, printed)")
    p.add_argument("--max-steps", type=nonnegative_int, default=None,
                   help="the step budget of a run (default: the environment's)")


def run(args: argparse.Namespace) -> int:
    """Serve the test until the input ends (or ``quit``), or, on a socket, until Ctrl-C."""
    from flowtest_env.runtime import TestRuntime
    from flowtest_env.sources import load_test

    if args.max_steps == 0:
        raise ProblemError("--max-steps must be at least 1")
    artifact = load_test(args.test)
    if args.port is None:
        # bytes that are not UTF-8 become U+FFFD (a request that is then answered with an error), not a crash
        inp = io.TextIOWrapper(sys.stdin.buffer, encoding="utf-8", errors="replace") if hasattr(sys.stdin, "buffer") else sys.stdin
        serve_stream(TestRuntime(artifact, args.max_steps), inp, sys.stdout)
        return EXIT_OK
    try:
        server = make_server(artifact, args.port, args.max_steps)
    except OSError as exc:
        raise ProblemError(f"--port {args.port}: cannot listen on 127.0.0.1:{args.port} ({exc.strerror or exc})") from None
    with server:
        port = int(server.server_address[1])
        sys.stderr.write(f"flowtest: serving {artifact.name} on 127.0.0.1:{port}\n")
        sys.stderr.flush()
        server.serve_forever()
    return EXIT_OK


COMMAND = Command("serve", "run a synthesized test as a runtime for another process, over JSON lines", add_arguments, run)
