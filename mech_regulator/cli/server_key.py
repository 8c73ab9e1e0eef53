"""What the command server (cli/server.py) and its client (cli/server_client.py) must share: the key, the
folder and the checks of a peer.

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

import hashlib
import json
import os
import socket
import stat
import struct
import sys
from pathlib import Path

SERVER_VARIABLE = "MECH_REGULATOR_SERVER"  # off: never use or start a server


IDLE_VARIABLE = "MECH_REGULATOR_SERVER_IDLE"  # [s] without a command after which the server stops


IDLE_DEFAULT = 600.0  # [s]


KEYED_PREFIXES = ("MECH_REGULATOR_", "NUMBA_", "PYTHON", "OPENBLAS_", "OMP_", "MKL_", "LC_")


KEYED_NAMES = ("LANG", "HOME", "XDG_CACHE_HOME")


UNKEYED = ("MECH_REGULATOR_SERVER", "MECH_REGULATOR_PROGRESS_INTERVAL", "MECH_REGULATOR_AUTO_PATH")
"""Variables left out of the key: the server's own, and those a command reads afresh where it uses them (from the
client's environment in the child)."""


SOCKET_PATH_MAX = 100  # bytes: a Unix socket's path must fit in sun_path (108 on Linux)


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


def socket_path(digest: str) -> Path:
    """The Unix socket of the server whose key has this digest (key_digest), in server_folder."""
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
