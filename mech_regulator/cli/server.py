"""The command server: a resident process that has imported the command line and the physics core (numpy, scipy,
numba, the scene, the model, the solvers, the analysis) and loaded the fast path's compiled steppers, and forks a
child per command, so that a warm `simulate` pays a fork instead of the imports (about 0.8 s of a 0.8 to 1.2 s run).
The remedy of Android's zygote, Julia's DaemonMode, dmypy and the Gradle daemon for the start-up of a JIT.

The server (`serve`) forks a child per command; the child puts the client's descriptors on 0, 1 and 2 (so that
isatty, the progress bar, colours and output files are those of the client's terminal or pipe), takes the client's
working folder, environment, sys.path, sys.argv and umask, Python's default signal handlers and new sys.stdin,
stdout and stderr buffered as Python buffers them for these descriptors, runs the command line (cli.command.run_command)
and exits through the interpreter's normal exit; the server reaps it and sends the client its exit code. After a
command it loads what its child needed and it lacks: the generated module of the child's scene
(codegen.load_scene_module) and the steppers numba's disk cache holds by now (the server never compiles a stepper:
solvers/compiled/warm.py's background process does). It stops after MECH_REGULATOR_SERVER_IDLE seconds without a
command (default 600), when the source of its package changes (it could serve nobody again), on SIGTERM and on
`mech-regulator server stop`. One server per key: it holds an exclusive lock on KEY.lock for its life.

This module is the server; the client is server_client.py, what the two must share (the key, the folder, the
peer's checks) server_key.py.
"""

from __future__ import annotations

import json
import os
import select
import signal
import socket
import struct
import sys
import time
from collections.abc import Callable
from typing import NoReturn

from mech_regulator.cli.server_key import (
    idle_limit,
    key_digest,
    peer_refusal,
    server_key,
    socket_path,
    source_fingerprint,
)

PRELOADED = (
    "numpy",
    "scipy.integrate",
    "numba",
    "yaml",
    "tqdm",
    "mech_regulator.cli.main",
    "mech_regulator.cli.report.analysis_text",
    "mech_regulator.cli.report.data",
    "mech_regulator.cli.report.machine_text",
    "mech_regulator.cli.report.outputs",
    "mech_regulator.cli.report.terminal",
    "mech_regulator.scene",
    "mech_regulator.model",
    "mech_regulator.solvers",
    "mech_regulator.solvers.advice",
    "mech_regulator.solvers.cosim",
    "mech_regulator.solvers.compiled.run",
    "mech_regulator.solvers.compiled.warm",
    "mech_regulator.analysis",
    "mech_regulator.analysis.self_check",
    "mech_regulator.analysis.kinematics",
    "mech_regulator.analysis.engine",
    "mech_regulator.viz.plots",
)
"""What the server imports before its first command: what simulate and the analysis commands import, and their
pictures (matplotlib with its Agg backend: --plot)."""
SOURCE_CHECK = 10.0  # [s] between two checks of the package's source by the server


class _Request:
    """A command taken by a forked child: what the client sent and the descriptors it attached."""

    def __init__(self, message: dict, descriptors: list[int], report: int):
        self.message, self.descriptors, self.report = message, descriptors, report

    def run(self, run_command: Callable[[list[str]], int]) -> int:
        """The command run in this child process as in the client's by `run_command` (argv -> exit code): its exit
        code (SystemExit's as the interpreter makes it). Then it writes what it loaded to the report pipe."""
        message = self.message
        for target, descriptor in enumerate(self.descriptors):
            os.dup2(descriptor, target)
            if descriptor > 2:
                os.close(descriptor)
        for number in (signal.SIGTERM, signal.SIGHUP, signal.SIGCHLD):
            signal.signal(number, signal.SIG_DFL)
        signal.signal(signal.SIGINT, signal.default_int_handler)
        os.environ.clear()
        os.environ.update(message["environment"])
        time.tzset()
        os.umask(message["umask"])
        sys.path[:] = message["path"]
        sys.argv = [message["argv0"], *message["argv"]]
        _fresh_standard_streams()
        try:
            os.chdir(message["cwd"])
        except OSError as error:  # the working folder is gone
            print(
                f"mech-regulator: cannot enter the working folder {message['cwd']}: {error.strerror}", file=sys.stderr
            )
            return 1
        try:
            return run_command(message["argv"])
        except SystemExit as exit:  # argparse's exit 2, as the interpreter turns it into an exit code
            if exit.code is None or isinstance(exit.code, int):
                return exit.code or 0
            print(exit.code, file=sys.stderr)
            return 1
        finally:
            with os.fdopen(self.report, "w") as report:
                json.dump(_loaded_scene_modules(), report)


def _fresh_standard_streams() -> None:
    """New sys.stdin, stdout and stderr on descriptors 0, 1 and 2, with the encoding and errors of the server's and
    the buffering Python gives these descriptors at its start: line-buffered on a terminal (stderr always),
    written through when unbuffered (PYTHONUNBUFFERED, which the server's own stdout shows)."""
    import io

    buffered = not (isinstance(sys.stdout, io.TextIOWrapper) and sys.stdout.write_through)
    for descriptor, name in enumerate(("stdin", "stdout", "stderr")):
        old = getattr(sys, name)
        writing = descriptor > 0
        raw = open(descriptor, "wb" if writing else "rb", buffering=-1 if buffered or not writing else 0, closefd=False)
        stream = io.TextIOWrapper(
            raw,
            encoding=old.encoding,
            errors=old.errors,
            newline="\n",
            line_buffering=buffered and writing and (descriptor == 2 or os.isatty(descriptor)),
            write_through=writing and not buffered,
        )
        setattr(sys, name, stream)
        setattr(sys, f"__{name}__", stream)


def _loaded_scene_modules() -> list[str]:
    codegen = sys.modules.get("mech_regulator.solvers.compiled.codegen")
    return codegen.loaded_scene_modules() if codegen is not None else []


class _Server:
    """The server's state: its socket, its lock, its running children, what it loaded."""

    def __init__(self, lock, key: str):
        self.lock, self.key, self.digest = lock, key, key_digest(key)
        keyed = json.loads(key)  # serve() has checked it is this process's own
        self.package, self.source = keyed["package"], keyed["source"]
        self.path = socket_path(self.digest)
        self.pid = os.getpid()
        self.idle_limit = idle_limit()
        self.children: dict[int, tuple[socket.socket, int]] = {}  # pid -> (client connection, report pipe)
        self.steppers: list[str] = []
        self.served = 0
        self.last = time.monotonic()  # the end of the last command (or the start)
        self.stopping = False
        self.listener: socket.socket | None = None

    def preload(self) -> None:
        """Import PRELOADED and load the steppers numba's disk cache holds (never compiling one)."""
        import importlib

        for name in PRELOADED:
            importlib.import_module(name)
        self.load_cached_steppers()

    def load_cached_steppers(self) -> None:
        from mech_regulator.solvers.compiled import FAST_METHODS
        from mech_regulator.solvers.compiled.steppers import stepper
        from mech_regulator.solvers.compiled.warm import stepper_cached

        for method in FAST_METHODS:
            if method not in self.steppers and stepper_cached(method):
                stepper(method)
                self.steppers.append(method)

    def run(self) -> _Request | None:
        """Serve until stopped; returns the request in a forked child (None in the server when it ends)."""
        wake_read, wake_write = os.pipe()
        os.set_blocking(wake_write, False)
        signal.set_wakeup_fd(wake_write)
        signal.signal(signal.SIGCHLD, lambda number, frame: None)  # wakes select through the wakeup descriptor
        signal.signal(signal.SIGTERM, lambda number, frame: setattr(self, "stopping", True))
        self.path.unlink(missing_ok=True)  # a dead server's: this one holds the lock
        self.listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.listener.bind(os.fspath(self.path))
        self.listener.listen(16)
        print(f"serving on {self.path} (pid {self.pid})", flush=True)
        checked = time.monotonic()
        try:
            while True:
                now = time.monotonic()
                if now - checked > SOURCE_CHECK:
                    checked = now
                    if source_fingerprint(self.package) != self.source:
                        print("the package's source changed: stopping", flush=True)
                        self.stopping = True
                if self.stopping or (not self.children and now - self.last > self.idle_limit):
                    self._close_listener()
                    if not self.children:
                        return None
                sockets = [wake_read] + ([self.listener] if self.listener is not None else [])
                ready, _, _ = select.select(sockets, [], [], min(SOURCE_CHECK, self.idle_limit))
                if wake_read in ready:
                    os.read(wake_read, 512)
                self._reap()
                if self.listener is not None and self.listener in ready:
                    request = self._accept(self.listener)
                    if request is not None:  # in the child
                        signal.set_wakeup_fd(-1)
                        for descriptor in (wake_read, wake_write):
                            os.close(descriptor)
                        return request
        finally:
            if os.getpid() == self.pid:
                self._close_listener()

    def _close_listener(self) -> None:
        if self.listener is not None:
            self.listener.close()
            self.listener = None
            self.path.unlink(missing_ok=True)

    def _accept(self, listener: socket.socket) -> _Request | None:
        """Take one connection from `listener`: answer status or stop, or fork the command's child (returned in the
        child)."""
        connection, _ = listener.accept()
        connection.settimeout(5.0)  # a client that sends nothing does not hold the server
        try:
            message, descriptors = _receive(connection)
        except (OSError, ValueError):
            connection.close()
            return None
        try:
            refusal = peer_refusal(connection)
            if refusal is not None:  # the client runs the command itself
                _answer(connection, {"refused": refusal})
            elif message.get("op") == "status":
                _answer(connection, self.status())
            elif message.get("op") == "stop":
                self.stopping = True
                _answer(connection, {"stopping": True})
            elif message.get("op") == "run" and message.get("key") != self.key:
                _answer(connection, {"refused": "another key"})
            elif message.get("op") == "run" and len(descriptors) == 3:
                return self._fork(connection, message, descriptors)
        except OSError:
            pass
        finally:
            if os.getpid() == self.pid:
                for descriptor in descriptors:
                    os.close(descriptor)
                if connection.fileno() >= 0 and not any(connection is kept for kept, _ in self.children.values()):
                    connection.close()
        return None

    def _fork(self, connection: socket.socket, message: dict, descriptors: list[int]) -> _Request | None:
        report_read, report_write = os.pipe()
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:  # the child: nothing of the server's stays open in it
            os.close(report_read)
            if self.listener is not None:
                self.listener.close()
            self.lock.close()
            connection.close()
            for kept, report in self.children.values():
                kept.close()
                os.close(report)
            return _Request(message, descriptors, report_write)
        os.close(report_write)
        self.children[pid] = (connection, report_read)
        connection.settimeout(None)
        _answer(connection, {"pid": pid})
        return None

    def _reap(self) -> None:
        """Collect the ended children: send each client its exit code, then load what the child loaded."""
        while self.children:
            pid, status = os.waitpid(-1, os.WNOHANG)
            if pid == 0:
                return
            connection, report = self.children.pop(pid)
            code = os.waitstatus_to_exitcode(status)
            try:
                _answer(connection, {"exit": code} if code >= 0 else {"signal": -code})
            except OSError:
                pass  # the client went away
            connection.close()
            with os.fdopen(report) as pipe:
                text = pipe.read()
            self.served += 1
            self._load_after(text)

    def _load_after(self, report: str) -> None:
        """Load the scene modules the child loaded (numba's cache has them: the child loaded or compiled them) and
        the steppers compiled since."""
        try:
            digests = json.loads(report) if report else []
            if digests:
                from mech_regulator.solvers.compiled.codegen import load_scene_module

                for digest in digests:
                    load_scene_module(digest)
            self.load_cached_steppers()
        except Exception as error:  # a half-written cache file: the next child loads it itself
            print(f"could not preload after a command: {error!r}", flush=True)
        self.last = time.monotonic()

    def status(self) -> dict:
        from mech_regulator.solvers.compiled.codegen import loaded_scene_modules

        return {
            "pid": self.pid,
            "key": self.key,
            "digest": self.digest,
            "socket": os.fspath(self.path),
            "idle_s": 0.0 if self.children else time.monotonic() - self.last,
            "idle_limit_s": self.idle_limit,
            "served": self.served,
            "running": len(self.children),
            "modules": len(sys.modules),
            "steppers": self.steppers,
            "scene_modules": len(loaded_scene_modules()),
        }


def _receive(connection: socket.socket) -> tuple[dict, list[int]]:
    """A message sent by _send: its JSON and the descriptors attached."""
    header, descriptors, _, _ = socket.recv_fds(connection, 8, 3)
    while 0 < len(header) < 8:
        header += connection.recv(8 - len(header))
    if len(header) < 8:
        raise ValueError("no message")
    (length,) = struct.unpack("!Q", header)
    payload = bytearray()
    while len(payload) < length:
        chunk = connection.recv(min(length - len(payload), 1 << 20))
        if not chunk:
            raise ValueError("a message cut short")
        payload += chunk
    return json.loads(payload), descriptors


def _answer(connection: socket.socket, message: dict) -> None:
    connection.sendall(json.dumps(message).encode() + b"\n")


def serve(lock_descriptor: int, key: str, run_command: Callable[[list[str]], int]) -> int:
    """The server's program (BOOTSTRAP): check the key, preload, serve; in a forked child, run its command with
    `run_command` (argv -> exit code)."""
    lock = os.fdopen(lock_descriptor, "a")  # held since start_server took it
    if server_key() != key:
        print(f"this process's key differs from its client's; not serving\n{server_key()}\n{key}", flush=True)
        return 1
    server = _Server(lock, key)
    server.preload()
    import gc

    gc.freeze()  # what is loaded now stays out of the collector's passes: the children's pages stay shared
    request = server.run()
    if request is None:
        return 0
    _exit(request.run(run_command))


def _exit(code: int) -> NoReturn:
    """End a child as the interpreter ends a process — its non-daemon threads joined, the atexit functions run,
    stdout and stderr flushed (exit code 120 when that fails) — without tearing down the server's 1200 modules one
    by one (0.15 s)."""
    import atexit
    import threading

    threading._shutdown()  # type: ignore[attr-defined]  # the interpreter's own end of a process
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            code = 120
    os._exit(code)
