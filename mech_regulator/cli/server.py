"""The command server: a resident process that has imported the command line and the physics core (numpy, scipy,
numba, the scene, the model, the solvers, the analysis) and loaded the fast path's compiled steppers, and forks a
child per command, so that a warm `simulate` pays a fork instead of the imports (about 0.8 s of a 0.8 to 1.2 s run).
The remedy of Android's zygote, Julia's DaemonMode, dmypy and the Gradle daemon for the start-up of a JIT.

The client (`through_server`, called by the entry point cli.entry before any heavy import: this module imports the
standard library only): a served command (cli.SERVED_COMMANDS: the physics core only, no threads, ROS, Dask or
worker processes) connects to the Unix socket of the server whose key matches, sends its argv, working folder, whole
environment, sys.path and umask with its stdin, stdout and stderr descriptors (SCM_RIGHTS), forwards SIGINT, SIGTERM
and SIGHUP to the child the server names (and stops it with itself on Ctrl-Z), and ends as the child ended (its exit
code, or the signal that killed it). When no server answers, the command runs in its own process as without a
server and starts one, detached, for the next commands, saying so in one line on stderr — except in a CI job (the
variable CI set: `in_ci`), where it starts none unless MECH_REGULATOR_SERVER=on. MECH_REGULATOR_SERVER=off: never a
server.

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

The key (`server_key`) is everything that must match for the server's code to be the command's: the package's
version, folder and a fingerprint of its source (path, size and modification time of every .py file), the Python
(sys.executable, its flags, sys.path less its first entry, the modification times of the site-packages folders,
which an install changes) and the environment variables that change behaviour: MECH_REGULATOR_* (but UNKEYED:
the server's own and those a command reads afresh where it uses them), NUMBA_*, PYTHON*, the BLAS and OpenMP ones,
the locale's, HOME and XDG_CACHE_HOME (the compile caches' default folder). The socket is named by a hash of the
key, and the server compares the whole key of every command: a server whose key does not match is never used. The
folder: $XDG_RUNTIME_DIR/mech_regulator, else ~/.cache/mech_regulator/server ($XDG_CACHE_HOME), private to the user
(mode 0700): made so, and checked to be so before every use (folder_refusal: a folder, not a link, the user's own,
no permission for anyone else); a folder that fails the check is not used (the command runs in its own process,
with a note saying why).

A command is served only where its result is the one it would have in its own process (peer_refusal, by the
server for every connection): the client is the same user with the same groups (the socket's peer credentials,
SO_PEERCRED, and /proc/PID/status), in the same mount namespace with the same root folder as the server (the
inodes of /proc/PID/ns/mnt and /proc/PID/root): else the files it names could be other files, or the permissions to
write them others. A client the server refuses runs the command in its own process, silently; the client in turn
uses only a server of its own user.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import os
import select
import signal
import socket
import stat
import struct
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import NoReturn

from mech_regulator.cli.start import SERVED_COMMANDS
from mech_regulator.processes import process_alive

SERVER_VARIABLE = "MECH_REGULATOR_SERVER"  # off: never use or start a server
IDLE_VARIABLE = "MECH_REGULATOR_SERVER_IDLE"  # [s] without a command after which the server stops
IDLE_DEFAULT = 600.0  # [s]
KEYED_PREFIXES = ("MECH_REGULATOR_", "NUMBA_", "PYTHON", "OPENBLAS_", "OMP_", "MKL_", "LC_")
KEYED_NAMES = ("LANG", "HOME", "XDG_CACHE_HOME")
UNKEYED = ("MECH_REGULATOR_SERVER", "MECH_REGULATOR_PROGRESS_INTERVAL", "MECH_REGULATOR_AUTO_PATH")
"""Variables left out of the key: the server's own, and those a command reads afresh where it uses them (from the
client's environment in the child)."""
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
READY_WAIT = 120.0  # [s] `server start` waits at most this for the server to answer
STOP_WAIT = 30.0  # [s] `server stop` waits at most this for a server to end (it finishes its running commands)
SOURCE_CHECK = 10.0  # [s] between two checks of the package's source by the server
SOCKET_PATH_MAX = 100  # bytes: a Unix socket's path must fit in sun_path (108 on Linux)
BOOTSTRAP = (
    "import sys, json; sys.path[:] = json.loads(sys.argv[1]); from mech_regulator.cli.server import serve; "
    "from mech_regulator.cli.command import run_command; sys.exit(serve(int(sys.argv[2]), sys.argv[3], "
    "run_command))"
)
"""The server's program (python -c): the client's sys.path first, so that it imports what the client imports; its
children run the command line with cli.command.run_command, which this module does not import (the command line
imports this module for its `server` command)."""


class ServerGone(Exception):
    """The server ended the connection before the command's exit code."""


# ---------------------------------------------------------------------------------------------
# The key and the folder


def source_fingerprint(folder: str) -> str:
    """A hash of the path (relative to folder), size and modification time of every .py file under folder:
    a changed, added or removed source file changes it (about 1 ms for the package's 90 files)."""
    entries = []
    for root, folders, files in os.walk(folder):
        folders[:] = sorted(name for name in folders if name != "__pycache__")
        for name in sorted(files):
            if name.endswith(".py"):
                path = os.path.join(root, name)
                status = os.stat(path)
                entries.append(f"{os.path.relpath(path, folder)} {status.st_size} {status.st_mtime_ns}")
    return hashlib.sha256("\n".join(entries).encode()).hexdigest()[:16]


def server_key() -> str:
    """The key of this process's command line (module docstring), as canonical JSON text."""
    import mech_regulator

    package = os.path.dirname(os.path.abspath(mech_regulator.__file__))
    installed = {
        entry: os.stat(entry).st_mtime_ns
        for entry in sys.path[1:]
        if entry.endswith(("site-packages", "dist-packages")) and os.path.isdir(entry)
    }
    environment = {
        name: value
        for name, value in os.environ.items()
        if (name.startswith(KEYED_PREFIXES) or name in KEYED_NAMES) and not name.startswith(UNKEYED)
    }
    return json.dumps(
        {
            "version": mech_regulator.__version__,
            "package": package,
            "source": source_fingerprint(package),
            "executable": sys.executable,
            "flags": [list(sys.flags), sys.warnoptions, sorted(map(str, sys._xoptions.items()))],
            "path": sys.path[1:],
            "installed": installed,
            "environment": environment,
        },
        sort_keys=True,
    )


def key_digest(key: str) -> str:
    """The key's short hash, the name of its server's socket, lock and log."""
    return hashlib.sha256(key.encode()).hexdigest()[:16]


def server_folder() -> Path:
    """The folder of the servers' sockets: $XDG_RUNTIME_DIR/mech_regulator, else
    $XDG_CACHE_HOME/mech_regulator/server or ~/.cache/mech_regulator/server."""
    runtime = os.environ.get("XDG_RUNTIME_DIR")
    if runtime:
        return Path(runtime) / "mech_regulator"
    cache = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(cache) / "mech_regulator" / "server"


def folder_refusal(folder: Path) -> str | None:
    """Why the servers' folder must not be used, or None (also while it does not exist: start_server makes it): it
    must be a folder (not a symbolic link to one) owned by this process's user with no permission for its group or
    others (mode 0700), so that no one else can place a socket there or reach this user's server."""
    try:
        status = os.lstat(folder)
    except FileNotFoundError:
        return None
    except OSError as error:
        return error.strerror or str(error)
    if not stat.S_ISDIR(status.st_mode):
        return "it is not a folder (a symbolic link or a file)"
    if status.st_uid != os.getuid():
        return f"it belongs to user id {status.st_uid}, not to this user ({os.getuid()})"
    if status.st_mode & 0o077:
        return f"its mode {stat.S_IMODE(status.st_mode):04o} lets others in (expected 0700)"
    return None


def peer_credentials(connection: socket.socket) -> tuple[int, int, int]:
    """(pid, uid, gid) of the process at the other end of a Unix socket (SO_PEERCRED), as the kernel recorded them at
    connect or listen."""
    layout = struct.Struct("3i")
    return layout.unpack(connection.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED, layout.size))


def peer_refusal(connection: socket.socket) -> str | None:
    """Why the client at the other end of the connection would get another result from this process than from its
    own, or None: another user or other groups (peer credentials, the Groups line of /proc/PID/status), another
    mount namespace or another root folder (the device and inode of /proc/PID/ns/mnt and /proc/PID/root against
    this process's); a client whose process cannot be looked at (another PID namespace) is refused too."""
    pid, uid, gid = peer_credentials(connection)
    if uid != os.getuid() or gid != os.getgid():
        return "another user"
    try:
        with open(f"/proc/{pid}/status") as status:
            groups = next(line.split()[1:] for line in status if line.startswith("Groups:"))
        if sorted(map(int, groups)) != sorted(os.getgroups()):
            return "other groups"
        for theirs, mine, what in (
            (f"/proc/{pid}/ns/mnt", "/proc/self/ns/mnt", "another mount namespace"),
            (f"/proc/{pid}/root", "/", "another root folder"),
        ):
            their, my = os.stat(theirs), os.stat(mine)
            if (their.st_dev, their.st_ino) != (my.st_dev, my.st_ino):
                return what
    except (OSError, StopIteration, ValueError):
        return "a process whose view of the files cannot be compared"
    return None


def _socket_path(digest: str) -> Path:
    return server_folder() / f"{digest}.sock"


def idle_limit() -> float:
    """Seconds without a command after which the server stops: $MECH_REGULATOR_SERVER_IDLE when a number > 0, else
    IDLE_DEFAULT (with a note)."""
    text = os.environ.get(IDLE_VARIABLE, "")
    try:
        value = float(text) if text else IDLE_DEFAULT
    except ValueError:
        value = -1.0
    if not 0.0 < value < float("inf"):
        print(
            f"mech-regulator: note: {IDLE_VARIABLE}={text!r}: expected seconds > 0; the server stops after "
            f"{IDLE_DEFAULT:g} s idle",
            file=sys.stderr,
        )
        return IDLE_DEFAULT
    return value


# ---------------------------------------------------------------------------------------------
# The client


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
    path = _socket_path(key_digest(key))
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
            # the interpreter's flags (-O, -X ...) as this one's, as multiprocessing starts its processes
            flags = subprocess._args_from_interpreter_flags()  # type: ignore[attr-defined]
            process = subprocess.Popen(
                [sys.executable, *flags, "-c", BOOTSTRAP, json.dumps(sys.path), str(lock.fileno()), key],
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
        path = _socket_path(key_digest(key))
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


# ---------------------------------------------------------------------------------------------
# The server


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
        self.path = _socket_path(self.digest)
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
