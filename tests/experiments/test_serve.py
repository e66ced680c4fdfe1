"""``flowtest serve --port``: a server that one client cannot hold (issue 43) and that an
integrator can program against (issue 42): each connection its own session served at the
same time as the others, a bound on open sessions and a read timeout, answers that are
always valid JSON with a machine-readable error code, the verdict with its reason, a
request that ends the server, and history names that do not give the hidden test away."""

from __future__ import annotations

import io
import json
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from experiments.cli.serve import ERRORS, serve_stream
from flowtest_env.runtime import REFUSALS, TestRuntime

ROOT = Path(__file__).resolve().parents[2]


def strict_json(line: str) -> Any:
    """``line`` parsed as JSON proper: ``NaN`` or ``Infinity`` in it fail the test."""

    def refuse(name: str) -> Any:
        raise AssertionError(f"{name} in an answer: {line!r}")

    return json.loads(line, parse_constant=refuse)


class Server:
    """``flowtest serve TEST --port 0 ARGS`` in a child process, and clients for it."""

    def __init__(self, *args: str, test: str = "small-reactive") -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "experiments", "serve", test, "--port", "0", *args], cwd=ROOT, text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE
        )
        assert self.proc.stderr is not None
        line = self.proc.stderr.readline()
        assert line.startswith(f"flowtest: serving {test} on 127.0.0.1:"), line
        self.port = int(line.rsplit(":", 1)[1])

    def connect(self) -> Client:
        return Client(socket.create_connection(("127.0.0.1", self.port), timeout=10))

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
        self.proc.communicate(timeout=30)


class Client:
    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        self.file = sock.makefile("rw", encoding="utf-8", newline="\n")

    def ask(self, request: dict[str, Any] | str, within: float = 1.0) -> Any:
        """Send one request; its answer, which must come within ``within`` seconds."""
        t0 = time.perf_counter()
        self.file.write((request if isinstance(request, str) else json.dumps(request)) + "\n")
        self.file.flush()
        line = self.file.readline()
        took = time.perf_counter() - t0
        assert took < within, f"answered after {took:.2f} s"
        return strict_json(line)

    def close(self) -> None:
        self.file.close()
        self.sock.close()


@pytest.fixture
def server(request: pytest.FixtureRequest) -> Iterator[Server]:
    """A server; parametrize it indirectly with the command's extra arguments."""
    srv = Server(*getattr(request, "param", ()))
    yield srv
    srv.stop()


def test_an_idle_client_does_not_hold_the_server(server: Server) -> None:
    """Issue 43: one connection that sends nothing, another that sends half a line; a third
    client's requests are answered within a second each."""
    idle = server.connect()
    half = server.connect()
    half.sock.sendall(b'{"op": "res')
    client = server.connect()
    status = client.ask({"op": "reset"})["status"]
    assert status["state"] == [1, 0]
    assert client.ask({"op": "step", "action": "N"})["status"]["state"] == [0, 0]
    half.sock.sendall(b'et"}\n')  # the half line, completed, is answered in turn
    assert strict_json(half.file.readline())["status"]["step"] == 0
    for c in (idle, half, client):
        c.close()


def test_two_clients_play_at_once(server: Server) -> None:
    """Issue 42's acceptance: two clients play interleaved, each answered within a second,
    each with its own run."""
    a, b = server.connect(), server.connect()
    a.ask({"op": "reset"})
    b.ask({"op": "reset"})
    for state_a, state_b in (([0, 0], [1, 1]), ([0, 1], [1, 2])):
        assert a.ask({"op": "step", "state": state_a})["status"]["state"] == state_a
        assert b.ask({"op": "step", "state": state_b})["status"]["state"] == state_b
    assert a.ask({"op": "status"})["status"]["step"] == 2 and b.ask({"op": "status"})["status"]["state"] == [1, 2]
    a.close()
    b.close()


@pytest.mark.parametrize("server", [("--max-clients", "2", "--idle-timeout", "0.5")], indirect=True)
def test_sessions_are_bounded_and_an_idle_one_is_closed(server: Server) -> None:
    a, b = server.connect(), server.connect()
    a.ask({"op": "reset"})
    b.ask({"op": "reset"})
    third = server.connect()
    busy = strict_json(third.file.readline())  # answered at once, and closed
    assert busy["ok"] is False and busy["code"] == "busy" and "--max-clients" in busy["error"]
    assert third.file.readline() == ""
    time.sleep(0.8)  # a and b stay idle past --idle-timeout: each is told so and closed
    for c in (a, b):
        idle = strict_json(c.file.readline())
        assert idle["code"] == "idle" and "0.5 s (--idle-timeout)" in idle["error"]
        assert c.file.readline() == ""
    late = server.connect()  # their places are free again
    assert late.ask({"op": "reset"})["ok"] is True
    for c in (a, b, third, late):
        c.close()


def test_answers_are_always_json_and_errors_have_codes(server: Server) -> None:
    """``NaN`` is refused on the way in (an id ``NaN`` was echoed as non-JSON); an id that is
    no string, number or null is refused; every error carries a documented code."""
    c = server.connect()
    answers = [
        c.ask(line)
        for line in [
            '{"op": "reset", "id": NaN}',
            '{"op": "status", "id": Infinity}',
            '{"op": "status", "id": [1, {"a": 2}]}',
            '{"op": "status", "id": true}',
            '{"op": "status", "id": "' + "x" * 300 + '"}',
            '{"op": "reset", "id": 1e308}',
            '{"op": "step", "action": "NE", "id": "s1"}',
            '{"op": "step", "state": [9, 9]}',
            '{"op": "step"}',
            '{"op": "fly"}',
            "[1]",
            "not json",
        ]
    ]
    assert [a.get("code") for a in answers] == [
        "not_json",
        "not_json",
        "bad_id",
        "bad_id",
        "bad_id",
        None,
        "not_an_action",
        "not_a_state",
        "bad_request",
        "unknown_op",
        "not_an_object",
        "not_json",
    ]
    assert answers[5] == {"ok": True, "id": 1e308, "status": answers[5]["status"]}
    assert answers[6]["id"] == "s1" and "id" not in answers[2]
    assert all(a["code"] in {**ERRORS, **REFUSALS} for a in answers if not a["ok"])
    c.close()


def test_the_status_gives_the_verdict_with_its_reason_and_neutral_history_names(server: Server) -> None:
    c = server.connect()
    status = c.ask({"op": "reset"})["status"]
    assert status["reason"] is None and status["history_name"] == "q0"
    for state in ([0, 0], [0, 1], [1, 1], [1, 2], [0, 2]):
        status = c.ask({"op": "step", "state": state})["status"]
        assert "I1" not in status["history_name"] and "I2" not in status["history_name"]
    assert status["done"] and status["reason"] == "met the system objective in 5 steps"
    assert status["verdict"]["system_objective"] == "met"
    described = c.ask({"op": "describe"})
    assert (described["protocol"], described["version"]) == ("flowtest-serve", 2)
    assert "I1" not in json.dumps(described["test"])
    c.close()


@pytest.mark.parametrize("server", [("--reveal",)], indirect=True)
def test_reveal_names_the_histories(server: Server) -> None:
    c = server.connect()
    c.ask({"op": "reset"})
    assert c.ask({"op": "step", "state": [0, 0]})["status"]["history_name"] == "saw I1"
    c.close()


def test_shutdown_ends_the_server(server: Server) -> None:
    a, b = server.connect(), server.connect()
    a.ask({"op": "reset"})
    assert b.ask({"op": "shutdown", "id": 1}) == {"ok": True, "id": 1}
    server.proc.wait(timeout=10)
    assert server.proc.returncode == 0
    with pytest.raises(OSError):
        socket.create_connection(("127.0.0.1", server.port), timeout=2).close()
    a.close()
    b.close()


def test_shutdown_and_quit_end_a_session_on_standard_input() -> None:
    for op in ("quit", "shutdown"):
        out = io.StringIO()
        serve_stream(TestRuntime.load("small-reactive"), io.StringIO(f'{{"op":"{op}"}}\n{{"op":"reset"}}\n'), out)
        assert out.getvalue() == '{"ok":true}\n'


@pytest.mark.parametrize(
    "args,message",
    [
        (["--idle-timeout", "1e300"], "expected at most 86400 seconds"),
        (["--max-clients", "0"], "expected a number of sessions (1-1024)"),
        (["--max-steps", "0"], "expected a step budget (1-1000000000)"),
    ],
)
def test_serve_options_have_their_range(args: list[str], message: str) -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "experiments", "serve", "small-reactive", "--port", "0", *args], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 2 and proc.stderr.startswith("error: ") and message in proc.stderr, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
