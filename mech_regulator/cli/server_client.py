"""The command server's client (cli/server.py is the server).

The client (`through_server`, called by the entry point cli.entry before any heavy import: this module imports the
standard library only): a served command (cli.SERVED_COMMANDS: the physics core only, no threads, ROS, Dask or
worker processes) connects to the Unix socket of the server whose key matches, sends its argv, working folder, whole
environment, sys.path and umask with its stdin, stdout and stderr descriptors (SCM_RIGHTS), forwards SIGINT, SIGTERM
and SIGHUP to the child the server names (and stops it with itself on Ctrl-Z), and ends as the child ended (its exit
code, or the signal that killed it). When no server answers, the command runs in its own process as without a
server and starts one, detached, for the next commands, saying so in one line on stderr — except in a CI job (the
variable CI set: `in_ci`), where it starts none unless MECH_REGULATOR_SERVER=on. MECH_REGULATOR_SERVER=off: never a
server.
"""

from __future__ import annotations

import fcntl
import json
import os
import signal
import socket
import struct
import sys
import time
from pathlib import Path

from mech_regulator.cli.server_key import (
    SERVER_VARIABLE,
    SOCKET_PATH_MAX,
    folder_refusal,
    idle_limit,
    key_digest,
    peer_credentials,
    server_folder,
    server_key,
    socket_path,
)
from mech_regulator.cli.start import SERVED_COMMANDS
from mech_regulator.processes import process_alive, python_child

READY_WAIT = 120.0  # [s] `server start` waits at most this for the server to answer


STOP_WAIT = 30.0  # [s] `server stop` waits at most this for a server to end (it finishes its running commands)


BOOTSTRAP = (
    "from mech_regulator.cli.server import serve; from mech_regulator.cli.command import run_command; "
    "sys.exit(serve(int(sys.argv[2]), sys.argv[3], run_command))"
)
"""The server's program (processes.python_child: the client's sys.path, so that it imports what the client imports);
its children run the command line with cli.command.run_command, which this module does not import (the command line
imports this module for its `server` command)."""


class ServerGone(Exception):
    """The server ended the connection before the command's exit code."""


def through_server(argv: list[str]) -> int | None:
    """Run the command argv by the server of this key: its exit code, or None when it runs in this process instead
    (not a served command, MECH_REGULATOR_SERVER=off, or no server: one is then started for the next commands)."""
    if not argv or argv[0] not in SERVED_COMMANDS or "-h" in argv or "--help" in argv:
        return None
    setting = os.environ.get(SERVER_VARIABLE, "")
    if setting == "off":
        return None
    if setting not in ("", "on"):
        print(
            f"mech-regulator: note: {SERVER_VARIABLE}={setting!r}: expected on or off; this command runs without "
            "the command server",
            file=sys.stderr,
        )
        return None
    folder = server_folder()
    problem = folder_refusal(folder)
    if problem is not None:
        print(
            f"mech-regulator: note: the command server's folder {folder} is not private: {problem}; this command "
            f"runs without the server (chmod 700 it if it is yours, or set {SERVER_VARIABLE}=off)",
            file=sys.stderr,
        )
        return None
    key = server_key()
    path = socket_path(key_digest(key))
    if len(os.fsencode(path)) > SOCKET_PATH_MAX:
        return None  # a folder too deep for a socket: no server
    try:
        connection = _connect(path)
    except (FileNotFoundError, ConnectionRefusedError):  # none, or a dead one's socket
        if setting != "on" and in_ci():
            return None  # a CI job's commands leave no resident process behind unless asked to
        pid = start_server(key)
        if pid is not None:
            print(
                f"mech-regulator: started a command server (pid {pid}) that answers the next commands without "
                f"their imports; it stops after {idle_limit() / 60.0:g} min idle (stop it: `mech-regulator server "
                f"stop`; never use one: {SERVER_VARIABLE}=off)",
                file=sys.stderr,
            )
        elif server_starting(key):
            print(
                "mech-regulator: the command server is still starting (it answers once its imports are loaded); "
                "this command runs on its own",
                file=sys.stderr,
            )
        return None
    except OSError:
        return None
    with connection:
        if peer_credentials(connection)[1] != os.getuid():  # only a server of this user
            return None
        return run_request(connection, key, argv)


def in_ci() -> bool:
    """Whether this command runs in a continuous-integration job: the variable CI that GitHub Actions, GitLab CI,
    Travis, CircleCI, Buildkite and others set, with any value but empty, 0, false or no. There a command starts no
    server by itself (MECH_REGULATOR_SERVER=on still does), so that a job leaves no resident process behind."""
    return os.environ.get("CI", "").strip().lower() not in ("", "0", "false", "no")


def _connect(path: Path) -> socket.socket:
    connection = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        connection.connect(os.fspath(path))
    except OSError:
        connection.close()
        raise
    return connection


def run_request(connection: socket.socket, key: str, argv: list[str]) -> int | None:
    """Send the command argv over the connection and wait for its end, forwarding SIGINT, SIGTERM and SIGHUP to its
    child and stopping it with this process on Ctrl-Z (SIGTSTP): its exit code; None when the server refused it
    (another key) or could not take it."""
    umask = os.umask(0)
    os.umask(umask)
    try:
        request = {
            "op": "run",
            "key": key,
            "argv": argv,
            "argv0": sys.argv[0],
            "cwd": os.getcwd(),
            "environment": dict(os.environ),
            "path": sys.path,
            "umask": umask,
        }
    except OSError:  # the working folder is gone
        return None
    child: list[int] = []
    pending: list[int] = []

    def forward(number, frame) -> None:
        if child:
            _signal(child[0], number)
        else:
            pending.append(number)

    def suspend(number, frame) -> None:  # the child stops with this process and goes on with it
        if child:
            _signal(child[0], signal.SIGSTOP)
        signal.signal(signal.SIGTSTP, signal.SIG_DFL)
        os.kill(os.getpid(), signal.SIGTSTP)  # stopped here until continued
        signal.signal(signal.SIGTSTP, suspend)
        if child:
            _signal(child[0], signal.SIGCONT)

    handlers = {signal.SIGINT: forward, signal.SIGTERM: forward, signal.SIGHUP: forward, signal.SIGTSTP: suspend}
    before = {number: signal.signal(number, handler) for number, handler in handlers.items()}
    answer = None
    try:
        _send(connection, request, (0, 1, 2))
        replies = connection.makefile("rb")
        answer = _reply(replies)
        if "refused" in answer:
            answer = None
        else:
            child.append(answer["pid"])
            for number in pending:
                _signal(child[0], number)
            answer = _reply(replies)
    except (OSError, ServerGone):
        if child:
            _signal(child[0], signal.SIGTERM)
            print(
                f"mech-regulator: the command server ended during the command (its child {child[0]} was stopped); "
                f"run it again, or without the server: {SERVER_VARIABLE}=off",
                file=sys.stderr,
            )
            answer = {"exit": 1}
    finally:
        for number, handler in before.items():
            signal.signal(number, handler)
    if answer is None:  # not taken: this process runs the command, unless a signal came meanwhile
        for number in pending:
            os.kill(os.getpid(), number)
        return None
    if "signal" in answer:  # end as the child ended: by the same signal
        signal.signal(answer["signal"], signal.SIG_DFL)
        os.kill(os.getpid(), answer["signal"])
        return 128 + answer["signal"]
    return answer["exit"]


def _signal(pid: int, number: int) -> None:
    try:
        os.kill(pid, number)
    except ProcessLookupError:  # ended meanwhile
        pass


def _send(connection: socket.socket, message: dict, descriptors: tuple[int, ...] = ()) -> None:
    """A message: its length (8 bytes, with the descriptors attached), then its JSON."""
    payload = json.dumps(message).encode()
    socket.send_fds(connection, [struct.pack("!Q", len(payload))], list(descriptors))
    connection.sendall(payload)


def _reply(replies) -> dict:
    line = replies.readline()
    if not line.endswith(b"\n"):
        raise ServerGone
    return json.loads(line)


def server_starting(key: str) -> bool:
    """Whether the server of `key` holds its lock (it is starting: it has not answered yet)."""
    try:
        with open(server_folder() / f"{key_digest(key)}.lock", "a") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)  # released as the file closes
    except BlockingIOError:
        return True
    except OSError:
        return False
    return False


def start_server(key: str) -> int | None:
    """Start the server of `key`, detached (a new session; stdin from /dev/null, output to KEY.log), unless one holds
    KEY.lock already (running, or loading): its pid, or None. The lock is taken here and handed to the server,
    which holds it for its life."""
    import subprocess

    folder = server_folder()
    digest = key_digest(key)
    try:
        folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    except OSError:
        return None
    if folder_refusal(folder) is not None:  # made so, and still so
        return None
    try:
        lock = open(folder / f"{digest}.lock", "a")
    except OSError:
        return None
    with lock:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return None
        with open(folder / f"{digest}.log", "w") as log:
            process = subprocess.Popen(
                python_child(BOOTSTRAP, str(lock.fileno()), key),
                stdin=subprocess.DEVNULL,
                stdout=log,
                stderr=subprocess.STDOUT,
                cwd="/",
                start_new_session=True,
                pass_fds=(lock.fileno(),),
            )
    return process.pid


# ---------------------------------------------------------------------------------------------
# `mech-regulator server start|status|stop`


def server_command(action: str) -> int:
    """server start: start this environment's server unless running and wait until it answers, saying how long that
    took; status: each
    server of the folder (pid, key, idle time, what it loaded); stop: stop every server of the folder and wait
    until each has ended."""
    problem = folder_refusal(server_folder())
    if problem is not None:
        print(
            f"mech-regulator: the command server's folder {server_folder()} is not private: {problem}; no server "
            "is started, asked or stopped there (chmod 700 it if it is yours)",
            file=sys.stderr,
        )
        return 1
    if action == "start":
        key = server_key()
        path = socket_path(key_digest(key))
        if len(os.fsencode(path)) > SOCKET_PATH_MAX:
            print(
                f"mech-regulator: the server's folder {server_folder()} is too deep for a Unix socket (at most "
                f"{SOCKET_PATH_MAX} bytes); set XDG_RUNTIME_DIR to a shorter folder",
                file=sys.stderr,
            )
            return 1
        began = time.monotonic()
        started = start_server(key)
        deadline = began + READY_WAIT
        while (status := ask_server(path, {"op": "status"})) is None:
            ended = started is not None and not process_alive(started)
            if ended or time.monotonic() > deadline:
                print(
                    f"mech-regulator: the command server {'ended' if ended else 'did not answer'} within "
                    f"{READY_WAIT:g} s; see {path.with_suffix('.log')}",
                    file=sys.stderr,
                )
                return 1
            time.sleep(0.05)
        print(_status_line(status, key))
        waited = time.monotonic() - began
        print(
            f"started in {waited:.1f} s"
            if started is not None
            else f"was running already{'' if waited < 0.1 else f' (it answered after {waited:.1f} s: it was starting)'}"
        )
        return 0
    servers = [
        (path, status)
        for path in sorted(server_folder().glob("*.sock"))
        if (status := ask_server(path, {"op": "status"})) is not None
    ]
    if action == "status":
        key = server_key()
        for _, status in servers:
            print(_status_line(status, key))
        if not servers:
            print(
                f"no command server in {server_folder()}; the next served command starts one "
                f"({', '.join(sorted(SERVED_COMMANDS))}), unless {SERVER_VARIABLE}=off"
            )
        return 0
    for path, status in servers:
        ask_server(path, {"op": "stop"})
        deadline = time.monotonic() + STOP_WAIT
        while process_alive(status["pid"]) and time.monotonic() < deadline:
            time.sleep(0.02)
        if process_alive(status["pid"]):
            os.kill(status["pid"], signal.SIGKILL)
        print(f"stopped the command server pid {status['pid']} (key {status['digest']})")
    if not servers:
        print(f"no command server in {server_folder()}")
    return 0


def ask_server(path: Path, message: dict) -> dict | None:
    """The server's answer to message, None when none answers at path or it refuses this client (peer_refusal)."""
    try:
        with _connect(path) as connection:
            _send(connection, message)
            answer = _reply(connection.makefile("rb"))
    except (OSError, ServerGone, ValueError):
        return None
    return None if "refused" in answer else answer


def _status_line(status: dict, key: str) -> str:
    mine = "this environment's" if status["key"] == key else "another environment's (not used here)"
    return (
        f"command server pid {status['pid']}, key {status['digest']} ({mine}): idle {status['idle_s']:.0f} s "
        f"(stops after {status['idle_limit_s']:g} s), served {status['served']} command(s), "
        f"{status['running']} running; loaded {status['modules']} modules, steppers "
        f"{', '.join(status['steppers']) or 'none'}, {status['scene_modules']} scene module(s); "
        f"socket {status['socket']}"
    )
