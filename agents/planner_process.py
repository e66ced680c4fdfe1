"""Where a planner from outside FlowTest runs: its own process and session, every exchange
bounded in time, the whole process group ended with it.

:mod:`agents.external` plays ``cmd:`` and ``python:`` planners through three pieces:

* :func:`start_command` starts a planner program in a new session (its own process group),
  with its standard input, output and error on pipes; :func:`fork_child` forks this process
  into a new session that runs a Python planner (:mod:`agents.external`'s ``python:``), talking
  over a socket pair. Either gives a :class:`Running` planner.
* :class:`Wire` is FlowTest's end of those pipes: it writes a message, reads a line or a
  frame, each before a deadline (:class:`WireTimeout`), never blocks on a planner that does
  not read (non-blocking writes), never holds more than a bounded answer
  (:class:`WireTooLong`), and keeps the last lines of the planner's standard error. It waits
  in slices of :data:`TICK` seconds on the calling thread, so Ctrl-C and SIGTERM (which
  raise ``KeyboardInterrupt`` there) stop it within a slice whatever the planner does.
* :meth:`Running.end` (:class:`Session`) ends a planner: its input closed, a moment's
  grace, then ``SIGKILL`` to its whole process group, so children it started in the
  background do not outlive it.

POSIX only (``os.fork``, ``os.killpg``, ``poll``), as FlowTest is.
"""

from __future__ import annotations

import array
import fcntl
import os
import pickle
import select
import signal
import socket
import struct
import subprocess
import sys
import termios
import time
import warnings
import weakref
from collections import deque
from collections.abc import Callable
from typing import Any

TICK = 0.1
"""The longest one wait lasts before the calling thread looks at pending signals again (a
signal the kernel delivered to another thread is run by the main thread within it)."""

CHUNK = 1 << 16
"""Bytes read from a pipe at once."""

ERROR_LINES = 12
"""Lines of a planner's standard error kept for the report."""


class WireTimeout(Exception):
    """The deadline passed; ``writing`` tells whether FlowTest was still writing (the planner
    did not read its input) or waiting for an answer."""

    def __init__(self, writing: bool) -> None:
        super().__init__("writing" if writing else "reading")
        self.writing = writing


class WireClosed(Exception):
    """The planner closed its end (it exited, or closed its input or output)."""


class WireTooLong(Exception):
    """The planner sent more than the longest answer without ending it."""


class Wire:
    """FlowTest's end of a planner's pipes (see the module docstring).

    ``write_fd`` takes FlowTest's messages, ``read_fd`` gives the planner's answers (the
    same descriptor for a socket pair), ``error_fd`` its standard error (or ``None``);
    ``limit`` is the longest answer (bytes) held before :class:`WireTooLong`. The
    descriptors are made non-blocking; the caller owns and closes them.
    """

    def __init__(self, write_fd: int, read_fd: int, error_fd: int | None, limit: int) -> None:
        self.write_fd, self.read_fd, self.error_fd, self.limit = write_fd, read_fd, error_fd, limit
        for fd in {write_fd, read_fd, *([error_fd] if error_fd is not None else [])}:
            os.set_blocking(fd, False)
        self.inbox = bytearray()
        self.read_open = True
        self.error_open = error_fd is not None
        self.errors: deque[str] = deque(maxlen=ERROR_LINES)
        self._error_part = bytearray()

    # ---- writing
    def send(self, data: bytes, deadline: float) -> None:
        """Write all of ``data`` before ``deadline`` (``time.monotonic()``), reading what the
        planner writes meanwhile.

        Raises
        ------
        WireTimeout
            If the planner did not take it all in time (``writing`` is true).
        WireClosed
            If the planner's input is closed.
        """
        view = memoryview(data)
        while view:
            try:
                view = view[os.write(self.write_fd, view) :]
                continue
            except BlockingIOError:
                pass
            except OSError:  # a broken pipe, a closed socket
                raise WireClosed from None
            self._wait(deadline, writing=True)

    # ---- reading
    def line(self, deadline: float) -> bytes:
        """The next line the planner wrote (without its newline), before ``deadline``.

        Raises
        ------
        WireTimeout, WireClosed, WireTooLong
            No line in time, the planner's output ended, or a line longer than ``limit``.
        """
        while True:
            end = self.inbox.find(b"\n")
            if end >= 0:
                line = bytes(self.inbox[:end])
                del self.inbox[: end + 1]
                return line
            self._need_more(deadline)

    def frame(self, deadline: float) -> Any:
        """The next frame (a 4-byte length, then a pickle) from a forked Python planner."""
        while len(self.inbox) < 4 or len(self.inbox) < 4 + struct.unpack("!I", self.inbox[:4])[0]:
            self._need_more(deadline)
        n = struct.unpack("!I", self.inbox[:4])[0]
        body = bytes(self.inbox[4 : 4 + n])
        del self.inbox[: 4 + n]
        return pickle.loads(body)

    def unasked(self) -> tuple[bytes, bool]:
        """What the planner wrote that was not asked for yet (read without waiting), and
        whether its output has ended."""
        self._wait(0.0, writing=False, block=False)
        return bytes(self.inbox[:200]), not self.read_open

    def _need_more(self, deadline: float) -> None:
        if len(self.inbox) > self.limit:
            raise WireTooLong
        if not self.read_open:
            raise WireClosed
        self._wait(deadline, writing=False)

    # ---- waiting
    def _wait(self, deadline: float, writing: bool, block: bool = True) -> None:
        """Wait (at most :data:`TICK`) for the planner to take input (``writing``) or to
        write, and read whatever it wrote. Raises :class:`WireTimeout` past ``deadline``."""
        left = deadline - time.monotonic()
        if block and left <= 0:
            raise WireTimeout(writing)
        events: dict[int, int] = {}
        if writing:
            events[self.write_fd] = select.POLLOUT
        if self.read_open and len(self.inbox) <= self.limit:
            events[self.read_fd] = events.get(self.read_fd, 0) | select.POLLIN
        if self.error_open and self.error_fd is not None:
            events[self.error_fd] = select.POLLIN
        poller = select.poll()
        for fd, mask in events.items():
            poller.register(fd, mask)
        ready = poller.poll(int(1000 * min(left, TICK)) + 1 if block else 0)
        for fd, mask in ready:
            if mask & (select.POLLIN | select.POLLHUP | select.POLLERR):
                if fd == self.read_fd and self.read_open:
                    self._read_answers()
                if fd == self.error_fd and self.error_open:
                    self._read_errors()

    def _read_answers(self) -> None:
        while len(self.inbox) <= self.limit:
            data = _read_some(self.read_fd)
            if data is None:
                return
            if not data:
                self.read_open = False
                return
            self.inbox += data

    def _read_errors(self) -> None:
        assert self.error_fd is not None
        while (data := _read_some(self.error_fd)) is not None:
            if not data:
                self.error_open = False
                if self._error_part:
                    self.errors.append(self._error_part.decode("utf-8", "replace")[:300])
                return
            self._error_part += data
            *lines, rest = self._error_part.split(b"\n")
            for line in lines[-ERROR_LINES:]:
                self.errors.append(line.decode("utf-8", "replace").rstrip("\r")[:300])
            self._error_part = bytearray(rest[-4096:])

    def unread_input(self) -> int | None:
        """Bytes FlowTest wrote that the planner has not read yet, where the system says
        (a pipe on Linux: ``FIONREAD`` on its write end); ``None`` for a socket pair or
        where it cannot be asked. Once the planner has answered a step, a correct planner
        has read that step's whole line, so anything left unread means it answered without
        reading."""
        if self.write_fd == self.read_fd:
            return None
        buf = array.array("i", [0])
        try:
            fcntl.ioctl(self.write_fd, termios.FIONREAD, buf, True)
        except OSError:
            return None
        return int(buf[0])

    def error_tail(self, n: int = 4) -> str:
        """The last ``n`` non-blank lines of the planner's standard error, joined by `` | ``."""
        if self.error_open:
            self._wait(0.0, writing=False, block=False)
        return " | ".join(line for line in list(self.errors)[-n:] if line.strip())


def _read_some(fd: int) -> bytes | None:
    """The bytes on ``fd`` now (``b""`` at its end or on an error), ``None`` if none yet."""
    try:
        return os.read(fd, CHUNK)
    except BlockingIOError:
        return None
    except OSError:
        return b""


def frame_bytes(value: Any) -> bytes:
    """``value`` as one frame: a 4-byte length, then its pickle (:meth:`Wire.frame`)."""
    body = pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL)
    return struct.pack("!I", len(body)) + body


# --------------------------------------------------------------------------- processes


class Session:
    """A planner process, leader of its own session: :meth:`exit_status` looks without
    reaping, :meth:`end` ends the whole process group (the pid stays reserved until the
    leader is reaped, so the group signalled is the planner's)."""

    def __init__(self, pid: int, reap: Callable[[float], int | None]) -> None:
        self.pid = pid
        self._reap = reap
        self.status: int | None = None

    def exit_status(self) -> int | None:
        """The leader's exit status (negative: the signal that ended it) once it has exited,
        else ``None``; the process is not reaped."""
        if self.status is not None:
            return self.status
        try:
            info = os.waitid(os.P_PID, self.pid, os.WEXITED | os.WNOHANG | os.WNOWAIT)
        except ChildProcessError:
            return None
        if info is None:
            return None
        return -info.si_status if info.si_code in (os.CLD_KILLED, os.CLD_DUMPED) else info.si_status

    def wait_exit(self, seconds: float) -> int | None:
        """:meth:`exit_status`, waiting up to ``seconds`` for it (in short sleeps that Ctrl-C
        interrupts)."""
        deadline = time.monotonic() + seconds
        while True:
            status = self.exit_status()
            if status is not None or time.monotonic() >= deadline:
                return status
            time.sleep(min(0.01, max(0.0, deadline - time.monotonic())))

    def end(self, grace: float = 0.0) -> int | None:
        """Give the leader ``grace`` seconds to exit, then kill the whole group and reap the
        leader; its exit status. A Ctrl-C during the grace kills at once, then goes on up."""
        if self.status is not None:
            return self.status
        try:
            if grace > 0:
                self.wait_exit(grace)
        finally:
            try:
                os.killpg(self.pid, signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                pass
            self.status = self._reap(5.0)
        return self.status


class Running:
    """A planner started in a session of its own: its :class:`Session`, the :class:`Wire` to
    it, and the files FlowTest holds open for it. :meth:`end` ends it once; so does the
    garbage collector, or the interpreter's exit, if nobody did."""

    def __init__(self, session: Session, wire: Wire, files: list[Any]) -> None:
        self.session, self.wire = session, wire
        self._files = files
        self._finalizer = weakref.finalize(self, _end, session, files, 0.0)

    def end(self, grace: float = 0.0, wait: float = 0.0) -> int | None:
        """Close FlowTest's ends of its pipes, wait up to ``wait`` seconds for it to exit by
        itself and ``grace`` more after its input closed, then kill its process group; its
        exit status (:meth:`Session.end`)."""
        self._finalizer.detach()
        if wait:
            self.session.wait_exit(wait)
        return _end(self.session, self._files, grace)


def _end(session: Session, files: list[Any], grace: float) -> int | None:
    for f in files:
        try:
            f.close()
        except OSError:
            pass
    return session.end(grace)


def start_command(words: list[str], cwd: str, limit: int) -> Running:
    """Start a planner program in its own session, its standard streams on pipes (answers
    up to ``limit`` bytes long).

    Raises
    ------
    OSError
        If it cannot be started.
    """
    proc = subprocess.Popen(words, cwd=cwd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, bufsize=0, start_new_session=True)
    assert proc.stdin is not None and proc.stdout is not None and proc.stderr is not None

    def reap(seconds: float) -> int | None:
        try:
            return proc.wait(timeout=seconds)
        except subprocess.TimeoutExpired:  # pragma: no cover - a process that outlives SIGKILL
            return None

    wire = Wire(proc.stdin.fileno(), proc.stdout.fileno(), proc.stderr.fileno(), limit)
    return Running(Session(proc.pid, reap), wire, [proc.stdin, proc.stdout, proc.stderr])


def fork_child(serve: Callable[[socket.socket], None], limit: int) -> Running:
    """Fork this process; the child leads a new session and runs ``serve(its socket)``, its
    standard input from ``/dev/null`` and its standard output into standard error (so a
    planner's prints never mix with a command's output), then exits. The parent gets the
    running child, talking over its end of a socket pair (frames up to ``limit`` bytes)."""
    ours, theirs = socket.socketpair()
    for stream in (sys.stdout, sys.stderr):  # not written twice by parent and child
        try:
            stream.flush()
        except (OSError, ValueError, AttributeError):
            pass
    with warnings.catch_warnings():
        # Python 3.12+ warns about fork() beside other threads: the child only runs the
        # planner and its socket, never a lock another thread of FlowTest could hold
        warnings.filterwarnings("ignore", category=DeprecationWarning, message=".*fork.*")
        pid = os.fork()
    if pid == 0:  # the child: never returns into the caller's code
        code = 0
        try:
            ours.close()
            os.setsid()
            signal.signal(signal.SIGINT, signal.SIG_DFL)
            signal.signal(signal.SIGTERM, signal.SIG_DFL)
            null = os.open(os.devnull, os.O_RDONLY)
            os.dup2(null, 0)
            os.dup2(2, 1)
            serve(theirs)
        except BaseException:  # the child ends here whatever happened
            code = 70
        finally:
            os._exit(code)
    theirs.close()

    def reap(seconds: float) -> int | None:
        deadline = time.monotonic() + seconds
        while True:
            got, status = os.waitpid(pid, os.WNOHANG)
            if got:
                return os.waitstatus_to_exitcode(status)
            if time.monotonic() >= deadline:  # pragma: no cover - a process that outlives SIGKILL
                return None
            time.sleep(0.005)

    return Running(Session(pid, reap), Wire(ours.fileno(), ours.fileno(), None, limit), [ours])
