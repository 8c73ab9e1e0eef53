"""The command server (cli/server.py): a command it serves gives the same stdout, output file, stderr and exit code
as in a process of its own, a bad scene the same message and exit 2; Ctrl-C at the client reaches the child (exit
130, the partial output written); a server of another key is never used; a server that vanishes mid-command ends
the command with a message and exit 1; `server stop` leaves no process; MECH_REGULATOR_SERVER=off starts none.

The suite runs with MECH_REGULATOR_SERVER=off (conftest.py); this module's server runs in a folder of its own
(XDG_RUNTIME_DIR), with an idle limit of 2 minutes in case all else fails, and is stopped at the end, by its pid if
it does not answer. No timing is asserted."""

from __future__ import annotations

import dataclasses
import fcntl
import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from mech_regulator.cli.server_client import ask_server, run_request
from mech_regulator.cli.server_key import key_digest, peer_refusal, server_key, source_fingerprint
from mech_regulator.errors import EXIT_INTERRUPTED
from mech_regulator.processes import process_alive

COMMAND = [sys.executable, "-m", "mech_regulator"]
TIMEOUT = 120.0  # [s] for any one command: a hung test fails instead of hanging the suite


@dataclasses.dataclass
class Served:
    """A server of this module: its client environment, folder, pid, socket and the first command's output."""

    env: dict[str, str]
    folder: str
    pid: int
    socket: Path
    first: subprocess.CompletedProcess

    def served(self) -> int:
        """How many commands the server has run."""
        return ask_server(self.socket, {"op": "status"})["served"]


def server_environment(folder: str) -> dict[str, str]:
    env = dict(
        os.environ, XDG_RUNTIME_DIR=folder, MECH_REGULATOR_SERVER_IDLE="120", MECH_REGULATOR_PROGRESS_INTERVAL="0"
    )
    env.pop("MECH_REGULATOR_SERVER", None)  # conftest's off
    env.pop("CI", None)  # a CI job starts no server by itself (tested below)
    return env


def run(argv: list[str], env: dict[str, str], cwd: Path | str | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([*COMMAND, *argv], env=env, cwd=cwd, capture_output=True, text=True, timeout=TIMEOUT)


def start(env: dict[str, str]) -> tuple[int, Path, str]:
    """`server start` (this environment's server, waited for): its pid, socket and the line saying how long it took."""
    started = run(["server", "start"], env)
    assert started.returncode == 0, started.stderr
    status, took = started.stdout.splitlines()
    return int(re.search(r"pid (\d+)", status).group(1)), Path(re.search(r"socket (\S+)", status)[1]), took


def stop(env: dict[str, str], pid: int, folder: str) -> None:
    """Stop the server (kill it by its pid if it lingers) and remove its folder."""
    try:
        run(["server", "stop"], env)
    finally:
        if process_alive(pid):
            os.kill(pid, signal.SIGKILL)
        shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture(scope="module")
def served():
    folder = tempfile.mkdtemp(prefix="mr-server-")  # short: a socket's path holds at most 108 bytes
    env = server_environment(folder)
    first = run(["describe", "lathe"], env)  # finds no server: runs here and starts one
    pid = None
    try:
        pid, path, took = start(env)  # the server the first command started: running, or still starting
        assert re.fullmatch(r"was running already( \(it answered after [0-9.]+ s: it was starting\))?", took), took
        yield Served(env, folder, pid, path, first)
    finally:
        match = re.search(r"\(pid (\d+)\)", first.stderr)
        for known in {pid, int(match[1]) if match else None} - {None}:
            stop(env, known, folder)


def test_the_first_served_command_runs_itself_and_starts_a_server(served):
    assert served.first.returncode == 0 and served.first.stdout.startswith("scene: lathe\n"), served.first.stdout
    [line] = served.first.stderr.splitlines()
    assert line.startswith(f"mech-regulator: started a command server (pid {served.pid})"), line
    assert "10 min idle" not in line and "2 min idle" in line and "server stop" in line
    assert "MECH_REGULATOR_SERVER=off" in line


def test_simulate_through_the_server_equals_simulate_in_process(served, tmp_path):
    """The same command in two folders (the CSV's name is printed): through the server, then in its own process
    with MECH_REGULATOR_SERVER=off and an empty server folder, which stays empty."""
    argv = ["simulate", "crank_slider_bench", "--quiet", "--out", "run.csv"]
    through, alone, empty = tmp_path / "through", tmp_path / "alone", tmp_path / "servers"
    for folder in (through, alone, empty):
        folder.mkdir()
    before = served.served()
    by_server = run(argv, served.env, through)
    assert served.served() == before + 1
    in_process = run(argv, dict(served.env, MECH_REGULATOR_SERVER="off", XDG_RUNTIME_DIR=str(empty)), alone)
    assert served.served() == before + 1 and list(empty.iterdir()) == []
    assert by_server.returncode == in_process.returncode == 0, by_server.stderr + in_process.stderr
    assert by_server.stdout == in_process.stdout and "csv" in by_server.stdout
    assert by_server.stderr == in_process.stderr
    assert (through / "run.csv").read_bytes() == (alone / "run.csv").read_bytes()


def test_a_bad_scene_key_through_the_server_gives_the_message_and_exit_2(served):
    argv = ["simulate", "lathe", "--set", "machine.nonsense=1"]
    before = served.served()
    by_server = run(argv, served.env)
    assert served.served() == before + 1
    in_process = run(argv, dict(served.env, MECH_REGULATOR_SERVER="off"))
    assert by_server.returncode == in_process.returncode == 2 and by_server.stdout == in_process.stdout == ""
    assert by_server.stderr == in_process.stderr and "machine.nonsense: unknown key" in by_server.stderr


def test_ctrl_c_at_the_client_interrupts_the_child(served, tmp_path):
    """SIGINT to the client once the child simulates (its first progress line past t = 0): the run stops as in-process, exit
    130, its summary says where, the CSV holds the run up to there."""
    before = served.served()
    client = subprocess.Popen(
        [*COMMAND, "simulate", "lathe", "--set", "scenario.duration=5000", "--out", "run.csv"],
        env=served.env,
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        estimate = client.stderr.readline()  # 1e7 rows of a CSV: large, said before the run
        assert estimate.startswith("mech-regulator: the outputs will take some 2 GB"), estimate
        line = client.stderr.readline()  # the work's start after its probe (t = 0), then its progress
        while line.startswith("simulating lathe: t = 0 / "):
            line = client.stderr.readline()
        assert line.startswith("simulating lathe: t = "), line
        client.send_signal(signal.SIGINT)
        out, err = client.communicate(timeout=TIMEOUT)
    finally:
        client.kill()
    assert client.returncode == EXIT_INTERRUPTED, err
    assert served.served() == before + 1
    stopped = float(re.match(r"scene lathe: interrupted at t = (\S+) s", out)[1])
    assert 0.0 < stopped < 5000.0 and "the outputs hold the run up to there" in err
    rows = (tmp_path / "run.csv").read_text().splitlines()
    assert rows[0].startswith("t,") and len(rows) > 1
    assert 0.0 <= float(rows[-1].split(",")[0]) <= stopped * (1.0 + 1e-5)  # the summary prints 6 digits


def test_a_server_of_another_key_is_not_used(served):
    """A stale source fingerprint: another socket name, and the server refuses the command (it runs nothing)."""
    key = ask_server(served.socket, {"op": "status"})["key"]
    stale = json.loads(key)
    stale["source"] = "0" * 16
    stale = json.dumps(stale, sort_keys=True)
    assert key_digest(stale) != served.socket.stem == key_digest(key)
    before = served.served()
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as connection:
        connection.connect(str(served.socket))
        assert run_request(connection, stale, ["describe", "lathe"]) is None
    assert served.served() == before


ROOT_AND_UNSHARE = pytest.mark.skipif(
    os.geteuid() != 0 or shutil.which("unshare") is None,
    reason="another mount namespace (unshare -m) and other users need root",
)


@ROOT_AND_UNSHARE
def test_a_client_in_another_mount_namespace_runs_the_command_itself(served, tmp_path):
    """The client mounts a tmpfs on view/ in a mount namespace of its own and writes view/run.csv: the server, which
    would write the folder's file of its own namespace, does not serve it; the client writes into its tmpfs, as a
    command without server would, silently."""
    (tmp_path / "view").mkdir()
    before = served.served()
    shell = (
        'mount -t tmpfs none view && "$0" -m mech_regulator simulate lathe --quiet --out view/run.csv && test -s '
        "view/run.csv"
    )
    done = subprocess.run(
        ["unshare", "-m", "sh", "-c", shell, sys.executable],
        cwd=tmp_path,
        env=served.env,
        capture_output=True,
        text=True,
        timeout=TIMEOUT,
    )
    assert done.returncode == 0 and "wrote view/run.csv" in done.stdout, done.stdout + done.stderr
    assert done.stderr == ""
    assert served.served() == before and list((tmp_path / "view").iterdir()) == []
    here = run(["simulate", "lathe", "--quiet", "--out", "view/run.csv"], served.env, tmp_path)  # this namespace
    assert here.returncode == 0 and served.served() == before + 1 and (tmp_path / "view" / "run.csv").exists()


@pytest.mark.skipif(os.geteuid() != 0, reason="a client of another user or other groups needs root to start it")
@pytest.mark.parametrize("user, groups, refusal", [(65534, [], "another user"), (0, [4242], "other groups")])
def test_the_server_refuses_a_client_of_another_user_or_other_groups(tmp_path, user, groups, refusal):
    """peer_refusal on a connection from a process started as another user, or with other supplementary groups."""
    folder = Path(tempfile.mkdtemp(prefix="mr-peer-"))
    try:
        folder.chmod(0o755)
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as listener:
            listener.bind(str(folder / "s"))
            (folder / "s").chmod(0o777)
            listener.listen(1)
            child = os.fork()
            if child == 0:  # the client: another user, or other groups; it connects and waits for the end
                try:
                    os.setgroups(groups)
                    os.setgid(user)
                    os.setuid(user)
                    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as connection:
                        connection.settimeout(TIMEOUT)  # a failing test does not leave it waiting
                        connection.connect(str(folder / "s"))
                        connection.recv(1)
                finally:
                    os._exit(0)
            try:
                connection, _ = listener.accept()
                with connection:
                    assert peer_refusal(connection) == refusal
            finally:
                os.waitpid(child, 0)
        mine, theirs = socket.socketpair()
        with mine, theirs:
            assert peer_refusal(mine) is None  # this very process
    finally:
        shutil.rmtree(folder, ignore_errors=True)


@pytest.mark.parametrize("kind", ["open", "not mine", "a link"])
def test_a_server_folder_that_is_not_private_is_not_used(tmp_path, kind):
    """The command runs in its own process with a note saying why, and no server is started or asked there."""
    if kind == "not mine" and os.geteuid() != 0:
        pytest.skip("giving a folder to another user needs root")
    runtime = Path(tempfile.mkdtemp(prefix="mr-open-"))
    try:
        folder = runtime / "mech_regulator"
        if kind == "a link":
            (runtime / "elsewhere").mkdir(mode=0o700)
            folder.symlink_to(runtime / "elsewhere")
        else:
            folder.mkdir(mode=0o700)
            folder.chmod(0o755 if kind == "open" else 0o700)
            if kind == "not mine":
                os.chown(folder, 65534, 65534)
        alone = run(["describe", "lathe"], server_environment(str(runtime)))
        assert alone.returncode == 0 and alone.stdout.startswith("scene: lathe\n"), alone.stderr
        why = {
            "open": "its mode 0755 lets others in (expected 0700)",
            "a link": "it is not a folder",
            "not mine": "it belongs to user id 65534, not to this user (0)",
        }[kind]
        assert alone.stderr.startswith(
            f"mech-regulator: note: the command server's folder {folder} is not private: {why}"
        ), alone.stderr
        assert len(alone.stderr.splitlines()) == 1 and "this command runs without the server" in alone.stderr
        assert list(folder.iterdir()) == []  # no lock, log or socket: no server started
        status = run(["server", "status"], server_environment(str(runtime)))
        assert status.returncode == 1 and "is not private" in status.stderr
    finally:
        shutil.rmtree(runtime, ignore_errors=True)


def test_the_key_follows_the_source_and_the_environment(tmp_path, monkeypatch):
    (tmp_path / "a.py").write_text("x = 1\n")
    first = source_fingerprint(str(tmp_path))
    os.utime(tmp_path / "a.py", ns=(0, 10**9))
    assert source_fingerprint(str(tmp_path)) != first
    key = server_key()
    monkeypatch.setenv("MECH_REGULATOR_PROGRESS_INTERVAL", "7")  # read where it is used: not keyed
    monkeypatch.setenv("MECH_REGULATOR_SERVER_IDLE", "7")
    assert server_key() == key
    monkeypatch.setenv("NUMBA_OPT", "1")
    assert server_key() != key


def test_a_server_that_vanishes_mid_command_ends_it_with_exit_1(tmp_path):
    folder = tempfile.mkdtemp(prefix="mr-vanish-")
    env = server_environment(folder)
    pid, _, took = start(env)
    try:
        assert re.fullmatch(r"started in [0-9.]+ s", took), took
        client = subprocess.Popen(
            [*COMMAND, "simulate", "lathe", "--set", "scenario.duration=5000"],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        try:
            first = client.stderr.readline()
            assert first.startswith("simulating lathe: t = "), first
            os.kill(pid, signal.SIGKILL)
            out, err = client.communicate(timeout=TIMEOUT)
        finally:
            client.kill()
        assert client.returncode == 1
        # the last line (after the child's last progress line, which SIGTERM may have cut short)
        found = re.search(
            r"mech-regulator: the command server ended during the command \(its child (\d+) was "
            r"stopped\); run it again, or without the server: MECH_REGULATOR_SERVER=off\n$",
            err,
        )
        assert found and out == "", err
        child = int(found[1])
        deadline = time.monotonic() + TIMEOUT
        while process_alive(child) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not process_alive(child)
    finally:
        stop(env, pid, folder)


def test_a_command_while_the_server_starts_says_it_runs_on_its_own(tmp_path):
    """A server that holds its lock but does not answer yet (still starting: here the test holds the lock): a served
    command runs in its own process, starts no second server and says so in one line."""
    folder = tempfile.mkdtemp(prefix="mr-start-")
    env = server_environment(folder)
    digest = subprocess.run(
        [
            sys.executable,
            "-c",
            "from mech_regulator.cli.server_key import key_digest, server_key; print(key_digest(server_key()))",
        ],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    servers = Path(folder) / "mech_regulator"
    servers.mkdir(mode=0o700)
    try:
        with open(servers / f"{digest}.lock", "a") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            alone = run(["describe", "lathe"], env)
        assert alone.returncode == 0 and alone.stdout.startswith("scene: lathe\n"), alone.stdout
        assert alone.stderr == (
            "mech-regulator: the command server is still starting (it answers once its imports "
            "are loaded); this command runs on its own\n"
        ), alone.stderr
        assert not any(servers.glob("*.sock")) and not any(servers.glob("*.log"))
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def test_server_stop_leaves_no_process(served):
    """Last of the module: it stops the module's server."""
    stopped = run(["server", "stop"], served.env)
    assert stopped.returncode == 0 and f"stopped the command server pid {served.pid}" in stopped.stdout
    assert not process_alive(served.pid) and not served.socket.exists()
    status = run(["server", "status"], served.env)
    assert status.stdout.startswith("no command server in ")


def test_a_ci_job_starts_no_server_unless_asked(tmp_path):
    """With CI set (as CI services do), a served command finding no server runs in its own process and starts
    none; MECH_REGULATOR_SERVER=on starts one even there."""
    folder = tempfile.mkdtemp(prefix="mr-ci-")
    try:
        for value in ("true", "1", "yes"):
            env = dict(server_environment(folder), CI=value)
            alone = run(["describe", "lathe"], env)
            assert alone.returncode == 0 and alone.stdout.startswith("scene: lathe\n"), alone.stdout
            assert alone.stderr == "", alone.stderr
            assert not any(Path(folder).rglob("*.sock")), list(Path(folder).rglob("*"))
        asked = run(["describe", "lathe"], dict(server_environment(folder), CI="true", MECH_REGULATOR_SERVER="on"))
        match = re.search(r"started a command server \(pid (\d+)\)", asked.stderr)
        assert asked.returncode == 0 and match, asked.stderr
        stop(dict(server_environment(folder), CI="true", MECH_REGULATOR_SERVER="on"), int(match[1]), folder)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
