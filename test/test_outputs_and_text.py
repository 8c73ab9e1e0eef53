"""Output files, scene text and the speed bound backwards.

- Every output path of every command is checked before any work (cli/report/outputs.py, check_output_paths and
  output_folder): a device or anything in /dev, a read-only folder (a private read-only bind mount in a mount
  namespace of its own: `unshare -m`, as root only), a full disk, a folder where a file is expected, two outputs
  that are one file: exit 2, one line naming the path and why, nothing written.
- A write that fails after the work (a disk that fills up) ends with one line and exit 1; the summary is printed and
  the other outputs are written (OutputWriter).
- A key given twice in a scene is an error naming the key and both places; control and bidirectional characters of a
  scene's name are escaped wherever the name reaches the terminal (report.terminal.terminal_text).
- A machine driven backwards beyond the trip speed ends its co-simulated run failed, on both paths; a blow-up
  backwards stops at MAX_SPEED as one forwards does.
"""

from __future__ import annotations

import errno
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from support import SOURCE_TREE, refused_line, run_cli, write_scene

from mech_regulator.cli.report import data, outputs, terminal
from mech_regulator.model import build_model
from mech_regulator.scene import SceneError, load_scene
from mech_regulator.scene.limits import MAX_SPEED
from mech_regulator.solvers import simulate
from mech_regulator.solvers.cosim import cosimulate

# Each command that writes files, with the option naming one: (argv before the option, option, a folder option?)
OUTPUTS = [
    (["simulate", "lathe"], "--out", False),
    (["simulate", "lathe"], "--plot", False),
    (["simulate", "lathe"], "--record", False),
    (["simulate", "lathe", "--exchange-step", "0.01"], "--out", False),
    (["simulate", "lathe", "--exchange-step", "0.01"], "--record", False),
    (["governor", "engine_direct"], "--plot", False),
    (["coupling", "two_mass", "--run-up", "1", "--delta", "0.1"], "--out", False),
    (["coupling", "two_mass", "--run-up", "1", "--delta", "0.1"], "--scene-out", False),
    (["coupling", "two_mass", "--run-up", "1", "--delta", "0.1"], "--plot", False),
    (["kinematics", "crank_slider_bench"], "--out", False),
    (["kinematics", "crank_slider_bench"], "--plot", False),
    (["engine", "engine"], "--out", False),
    (["engine", "engine"], "--plot", False),
    (["flywheel", "lathe", "--delta", "1/80"], "--plot", False),
    (["flywheel", "lathe", "--delta", "1/80"], "--record", False),
    (["structure", "six_bar_press"], "--plot", False),
    (["sweep", "lathe", "--jobs", "1"], "--out", True),
    (["bench", "speed", "--quick", "--no-mujoco"], "--out", True),
    (["bench", "accuracy", "--quick"], "--out", True),
    (["run", "lathe"], "--out", False),
]
IDS = [f"{' '.join(argv[:2])}{' cosim' if '--exchange-step' in argv else ''} {option}" for argv, option, _ in OUTPUTS]


def needs_rclpy(argv: list[str]) -> None:
    import importlib.util

    if argv[0] == "run" and importlib.util.find_spec("rclpy") is None:
        pytest.skip("run needs rclpy")


@pytest.mark.parametrize("argv, option, folder", OUTPUTS, ids=IDS)
def test_an_output_on_dev_full_is_refused_before_any_work(capsys, monkeypatch, argv, option, folder):
    needs_rclpy(argv)
    before = set(os.listdir("/dev"))
    line = refused_line(*run_cli(capsys, *argv, option, "/dev/full"))
    assert "'/dev/full" in line, line
    assert ("expected a folder" if folder else "it is in /dev, the kernel's") in line, line
    assert set(os.listdir("/dev")) == before  # nothing made there (--plot /dev/full would be /dev/full.png)


def test_the_kernel_s_files_a_pipe_and_two_outputs_in_one_file_are_refused(capsys, tmp_path):
    line = refused_line(*run_cli(capsys, "simulate", "lathe", "--out", "/proc/version"))  # a regular file there
    assert "cannot write '/proc/version': it is in /proc, the kernel's" in line, line
    os.mkfifo(tmp_path / "pipe.csv")
    line = refused_line(*run_cli(capsys, "simulate", "lathe", "--out", str(tmp_path / "pipe.csv")))
    assert f"'{tmp_path / 'pipe.csv'}': it is a device, a pipe or a socket, not a regular file" in line
    line = refused_line(
        *run_cli(capsys, "simulate", "lathe", "--plot", str(tmp_path / "a.png"), "--record", str(tmp_path / "a.png"))
    )
    assert "two of the command's outputs would be this one file" in line
    assert sorted(path.name for path in tmp_path.iterdir()) == ["pipe.csv"]


def test_an_existing_output_is_probed_without_being_changed(tmp_path):
    for content in (b"", b"keep me\n"):
        target = tmp_path / "old.csv"
        target.write_bytes(content)
        assert outputs.output_refusal(target) is None
        assert target.read_bytes() == content
    assert outputs.output_refusal(tmp_path / "new.csv") is None and not (tmp_path / "new.csv").exists()


def test_run_checks_every_file_it_derives_from_out(capsys, tmp_path):
    needs_rclpy(["run"])
    (tmp_path / "x.log").mkdir()  # the nodes' log would go there
    line = refused_line(*run_cli(capsys, "run", "lathe", "--out", str(tmp_path / "x.rrd")))
    assert f"cannot write '{tmp_path / 'x.log'}': it is a folder" in line, line
    line = refused_line(*run_cli(capsys, "run", "lathe", "--out", str(tmp_path / "x.csv")))
    assert f"--out '{tmp_path / 'x.csv'}': expected the recording's file (.rrd)" in line, line
    assert sorted(path.name for path in tmp_path.iterdir()) == ["x.log"]


# ----------------------------------------------------------------------------------------------
# A read-only folder and a full disk, for real: a mount namespace of the test's own


NAMESPACE_SCRIPT = """
import contextlib, io, json, sys
from mech_regulator.cli.main import main
{preamble}
results = []
for argv in json.loads(sys.argv[1]):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    results.append([code, out.getvalue(), err.getvalue()])
print(json.dumps(results))
"""


def in_private_mounts(
    tmp_path: Path, commands: list[list[str]], mounts: str, preamble: str = ""
) -> list[tuple[int, str, str]]:
    """Run the commands (argv lists of `mech-regulator`, in one process, after the Python `preamble`) in a mount
    namespace of their own, after the shell commands `mounts` there (cwd tmp_path): what each returned (exit code,
    stdout, stderr). Skips unless root and unshare work here."""
    if os.geteuid() != 0 or shutil.which("unshare") is None:
        pytest.skip("a private read-only mount needs root and unshare (util-linux)")
    probe = subprocess.run(["unshare", "-m", "true"], capture_output=True)
    if probe.returncode != 0:
        pytest.skip(f"unshare -m does not work here: {probe.stderr.decode(errors='replace').strip()}")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(SOURCE_TREE), os.environ.get("PYTHONPATH")])))
    shell = f'{mounts} && exec "$0" -c "$1" "$2"'
    done = subprocess.run(
        [
            "unshare",
            "-m",
            "sh",
            "-c",
            shell,
            sys.executable,
            NAMESPACE_SCRIPT.format(preamble=preamble),
            json.dumps(commands),
        ],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    return [tuple(result) for result in json.loads(done.stdout.splitlines()[-1])]


READ_ONLY = "mkdir -p ro && mount --bind ro ro && mount -o remount,bind,ro ro"


def test_every_output_in_a_read_only_folder_is_refused_before_any_work(tmp_path):
    import importlib.util

    cases = [
        (argv, option, folder)
        for argv, option, folder in OUTPUTS
        if argv[0] != "run" or importlib.util.find_spec("rclpy") is not None
    ]
    commands = [
        [*argv, option, str(tmp_path / "ro" / ("sub" if folder else "x.out"))] for argv, option, folder in cases
    ]
    commands.append(["sweep", "lathe", "--out", str(tmp_path / "ro")])  # an existing folder, read-only
    for (code, out, err), command in zip(in_private_mounts(tmp_path, commands, READ_ONLY), commands):
        line = refused_line(code, out, err)
        assert f"'{command[-1]}" in line and "Read-only file system" in line, (command, line)
    assert list((tmp_path / "ro").iterdir()) == []


ROOM_BEFORE_THE_RUN = (
    "import collections, shutil\n"
    "shutil.disk_usage = lambda folder: collections.namedtuple('usage', 'total used free')(10**15, 0, 10**15)"
)
"""Python that has the outputs' estimate (check_free_space) told of free space enough: a disk that fills up during a
run had room before it (test_disk_space.py tests the estimate)."""


def test_a_full_disk_is_refused_before_the_run_and_a_disk_filling_up_during_it_keeps_the_rest(tmp_path):
    """full/: a tmpfs of one page, filled; small/, tiny/ and both/: tmpfs of 40, 12 and 40 kB, which the lathe's
    CSV (about 1 MB) and recording (about 200 kB) overflow. The other output goes to a folder with room, or, in
    both/, to the same disk after the CSV filled it: the recording cannot write even its header (Rerun raises a
    RuntimeError of its own there, which once ended the command in a traceback). The disks fill up during the runs
    (ROOM_BEFORE_THE_RUN)."""
    mounts = (
        "mkdir -p full small tiny both && mount -t tmpfs -o size=4k none full"
        " && head -c 4096 /dev/zero > full/filler && mount -t tmpfs -o size=40k none small"
        " && mount -t tmpfs -o size=12k none tiny && mount -t tmpfs -o size=40k none both"
    )
    commands = [
        ["simulate", "lathe", "--quiet", "--out", "full/run.csv"],
        ["simulate", "lathe", "--quiet", "--json", "--out", "small/run.csv", "--plot", "run.png"],
        ["simulate", "lathe", "--quiet", "--json", "--record", "tiny/run.rrd", "--out", "run.csv"],
        ["simulate", "lathe", "--quiet", "--json", "--out", "both/run.csv", "--record", "both/run.rrd"],
    ]
    refused, csv_full, recording_full, both_full = in_private_mounts(tmp_path, commands, mounts, ROOM_BEFORE_THE_RUN)
    line = refused_line(*refused)
    assert "cannot write 'full/run.csv': No space left on device" in line, line
    for (code, out, err), failed, kept, key in (
        (csv_full, "small/run.csv", "run.png", "plot"),
        (recording_full, "tiny/run.rrd", "run.csv", "csv"),
    ):
        assert code == 1, err
        summary = json.loads(out)  # the summary still printed
        assert summary["status"] == "complete" and summary[key] == kept and failed not in out
        assert (tmp_path / kept).stat().st_size > 1000  # the other output written
        ours = [line for line in err.splitlines() if line.startswith("mech-regulator: ")]
        assert len(ours) == 1, err  # one line of ours (Rerun logs its own reason before it)
        assert ours[0].startswith(f"mech-regulator: writing '{failed}' failed: ") and "incomplete" in ours[0], err
    code, out, err = both_full
    assert code == 1 and json.loads(out)["status"] == "complete", err
    ours = [line for line in err.splitlines() if line.startswith("mech-regulator: ")]
    assert [line.split("' failed: ")[0] for line in ours] == [
        "mech-regulator: writing 'both/run.csv",
        "mech-regulator: writing 'both/run.rrd",
    ], err
    assert all("No space left on device" in line and "incomplete" in line for line in ours), err


def test_a_run_of_the_nodes_whose_disk_fills_up_ends_with_exit_1_and_says_which_outputs(tmp_path):
    """The ROS nodes' run on a tmpfs of 64 kB (its estimate told of room: ROOM_BEFORE_THE_RUN): the recording fills it
    during the run, then the recorder cannot write the CSV or the summary either. Each failure is one line (the recorder's, quoted by the launcher), the run ends with
    exit code 1, and nothing ends in a traceback."""
    pytest.importorskip("rclpy")
    from ros_support import next_domain_id

    if os.geteuid() != 0 or shutil.which("unshare") is None:
        pytest.skip("a private tmpfs needs root and unshare (util-linux)")
    shell = 'mkdir -p small && mount -t tmpfs -o size=64k none small && exec "$0" "$@"'
    done = subprocess.run(
        [
            "unshare",
            "-m",
            "sh",
            "-c",
            shell,
            sys.executable,
            "-c",
            f"{ROOM_BEFORE_THE_RUN}\nimport sys\nfrom mech_regulator.cli import entry\nsys.exit(entry())",
            "run",
            "engine_direct",
            "--duration",
            "0.3",
            "--quiet",
            "--domain-id",
            str(next_domain_id()),
            "--out",
            "small/run.rrd",
        ],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
        env=dict(
            os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(SOURCE_TREE), os.environ.get("PYTHONPATH")]))
        ),
    )
    code, out, err = done.returncode, done.stdout, done.stderr
    assert code == 1, err
    assert "Traceback" not in out + err, err
    assert "the recorder node ended with exit code 1: " in err and "output(s) could not be written" in err, err
    assert "No space left on device" in err and "cannot be read (written only in part" in err, err


def test_the_nodes_last_words_reach_the_launcher_when_their_log_cannot_be_written(tmp_path):
    """NodeLog on /dev/full (every write fails with ENOSPC): what the nodes write is still kept, in order, and the
    failed write is remembered; on a writable file the log holds the same bytes."""
    from mech_regulator.nodes.launch import NodeLog

    lines = [f"mech_regulator: recorder_node: line {number}\n".encode() for number in range(3000)]
    for target, fails in ((Path("/dev/full"), True), (tmp_path / "run.log", False)):
        with NodeLog(target) as log:
            writer = os.fork()
            if writer == 0:  # a node: writes through its own copy of the pipe's end, as a forked node does
                for line in lines:
                    os.write(log.fileno(), line)
                os._exit(0)
            log.follow()
            os.waitpid(writer, 0)
        assert log.tail() == b"".join(lines).decode()
        assert (log.error is not None and log.error.errno == errno.ENOSPC) == fails, log.error
        if not fails:
            assert target.read_bytes() == b"".join(lines)


def test_a_failed_write_after_the_run_keeps_the_summary_and_the_other_outputs(capsys, monkeypatch, tmp_path):
    def full_disk(path, *args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(data, "write_csv", full_disk)
    code, out, err = run_cli(
        capsys,
        "simulate",
        "lathe",
        "--quiet",
        "--set",
        "scenario.duration=1",
        "--out",
        str(tmp_path / "run.csv"),
        "--plot",
        str(tmp_path / "run.png"),
    )
    assert code == 1
    assert out.startswith("scene lathe: complete at t = 1 s") and f"wrote {tmp_path / 'run.png'}" in out
    assert "run.csv" not in out
    assert (
        err == f"mech-regulator: writing '{tmp_path / 'run.csv'}' failed: No space left on device; that file is "
        "incomplete\n"
    )
    assert (tmp_path / "run.png").stat().st_size > 1000


# ----------------------------------------------------------------------------------------------
# Scene text


def test_a_key_given_twice_is_an_error_naming_it_and_both_lines(tmp_path):
    path = write_scene(
        tmp_path, "name: twice\nbase: lathe\nscenario:\n  duration: 2.0\n  initial: {omega: 1.0}\n  duration: 3.0\n"
    )
    with pytest.raises(SceneError) as caught:
        load_scene(str(path))
    assert str(caught.value) == (
        f"{path}: the key 'duration' is given twice in one mapping, at line 4, column 3 and at "
        "line 6, column 3; expected it once (YAML would keep only the last)"
    )
    with pytest.raises(
        SceneError,
        match=r"--set scenario.initial: the key 'omega' is given twice in one mapping, at "
        r"line 1, column 2 and at line 1, column 12",
    ):
        load_scene("lathe", ["scenario.initial={omega: 1, omega: 2}"])


def test_a_merge_may_still_bring_keys_the_mapping_sets_itself(tmp_path):
    path = write_scene(
        tmp_path,
        "name: merged\nbase: lathe\nx-start: &start {phi: 0.5, omega: 3.0}\n"
        "scenario:\n  initial:\n    <<: *start\n    omega: 4.0\n",
    )
    with pytest.raises(SceneError, match="x-start") as caught:  # the unknown top-level key, not a duplicate
        load_scene(str(path))
    assert "twice" not in str(caught.value)


EVIL = "lathe\x1b[2J\x07\r\u202eevil\u2066"
ESCAPED = "lathe\\x1b[2J\\x07\\r\\u202eevil\\u2066"


def evil_scene(tmp_path: Path, governed: bool = False) -> Path:
    return write_scene(
        tmp_path,
        f"name: {json.dumps(EVIL)}\nbase: {'engine_direct' if governed else 'lathe'}\nscenario: {{duration: 0.5}}\n",
    )


def shown_raw(text: str) -> bool:
    return any(character in text for character in "\x1b\x07\r\u202e\u2066")


def test_a_scene_name_is_escaped_in_the_summary_the_progress_lines_and_errors(capsys, monkeypatch, tmp_path):
    monkeypatch.setenv("MECH_REGULATOR_PROGRESS_INTERVAL", "0")  # a progress line at every update (stderr no tty)
    code, out, err = run_cli(capsys, "simulate", str(evil_scene(tmp_path)), "--out", str(tmp_path / "run.csv"))
    assert code == 0, err
    assert out.startswith(f"scene {ESCAPED}: complete") and not shown_raw(out), out
    assert f"simulating {ESCAPED}: " in err and not shown_raw(err), err
    code, out, err = run_cli(capsys, "governor", str(evil_scene(tmp_path)))
    assert (
        code == 2
        and err
        == f"mech-regulator: scene '{ESCAPED}' has no governor: add a 'governor:' section (see docs/scenes.md)\n"
    ), err
    code, out, err = run_cli(capsys, "simulate", str(evil_scene(tmp_path)), "--quiet", "--exchange-step", "0.05")
    assert code == 0 and out.startswith(f"scene {ESCAPED}: complete") and not shown_raw(out + err), out + err
    code, out, err = run_cli(capsys, "describe", str(evil_scene(tmp_path)))
    assert code == 0 and out.startswith(f"scene: {ESCAPED}\n") and not shown_raw(out), out
    code, out, err = run_cli(capsys, "simulate", str(evil_scene(tmp_path)), "--quiet", "--json")
    assert code == 0 and json.loads(out)["scene"] == EVIL and not shown_raw(out)  # JSON escapes them itself


def test_terminal_text_keeps_lines_and_tabs_and_escapes_the_rest():
    assert terminal.terminal_text("a\tb\nc") == "a\tb\nc"
    assert (
        terminal.terminal_text("\x00\x1b\x7f\x9b\u200e\u200f\u202a\u202d\u2067\u2069\u061c")
        == "\\x00\\x1b\\x7f\\x9b\\u200e\\u200f\\u202a\\u202d\\u2067\\u2069\\u061c"
    )
    assert terminal.terminal_text("Drehzahl ω ü") == "Drehzahl ω ü"


# ----------------------------------------------------------------------------------------------
# The speed bound backwards


@pytest.mark.parametrize("path", ["reference", "fast"])
def test_a_load_driving_the_machine_backwards_beyond_the_trip_speed_ends_the_run(path):
    """The lathe (15 rad/s) under a load of 5000 N m from 1 s on turns backwards within 0.1 s; with a trip speed of
    20 rad/s the run fails at the first exchange beyond -20 rad/s, instead of running on backwards to its end."""
    model = build_model(
        load_scene(
            "lathe", ["scenario.load_events=[{time: 1.0, torque: 5000}]", "scenario.duration=2", f"solver.path={path}"]
        )
    )
    run = cosimulate(model, 0.01, overspeed_trip=20.0)
    assert run.status == "failed", run.message
    assert run.message.startswith(f"driven backwards at t = {run.times[-1]:.6g} s: omega = ")
    assert "beyond the trip speed 20 rad/s in reverse" in run.message
    assert 1.0 < run.times[-1] < 1.5 and run.states[1, -1] < -20.0 <= run.states[1, -2]
    free = cosimulate(model, 0.01)  # no trip: no bound but MAX_SPEED; the run goes on backwards to its end
    assert free.status == "complete" and free.times[-1] == pytest.approx(2.0) and free.states[1, -1] < -20.0


@pytest.mark.parametrize("path", ["reference", "fast"])
def test_a_blow_up_backwards_stops_at_max_speed_as_one_forwards(tmp_path, path):
    text = (
        "name: backwards\nmachine:\n  inertia: 0.5\n  drive: {type: constant, torque: -1.0e14}\n"
        "scenario:\n  initial: {phi: 0.0, omega: 10.0}\n  duration: 2.0\n"
        f"solver: {{method: RK45, rtol: 1.0e-6, sample_rate: 100.0, path: {path}}}\n"
    )
    trajectory = simulate(build_model(load_scene(str(write_scene(tmp_path, text)))))
    assert trajectory.status == "failed" and "the run blew up at t = " in trajectory.message
    assert f"is beyond {MAX_SPEED:g} rad/s" in trajectory.message and trajectory.stats.steps <= 50
    omega_end = trajectory(trajectory.t_end)[1]
    assert omega_end < -MAX_SPEED and np.isfinite(omega_end)
