"""Hostile and extreme input (docs/scenes.md, Limits): every scene ends at once with a result or a clear message -- exit
code 2 for bad input, 1 for a run that failed, never a traceback -- and nothing is written outside the run's folder.

Each case is written here. Besides the exit code and the message (it names the key), each asserts a bound on the work
done -- the YAML nodes composed, the right-hand-side evaluations, the steps -- never a wall-clock time. The limits are
in mech_regulator/scene/limits.py and docs/scenes.md ("Limits").
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from support import run_cli, write_scene

import mech_regulator.scene.loading as loading
import mech_regulator.solvers.time_domain as time_domain
from mech_regulator.model import MachineModel, build_model
from mech_regulator.nodes.launch import node_reason
from mech_regulator.nodes.outputs import default_recording
from mech_regulator.scene import SceneError, load_scene
from mech_regulator.scene.limits import (
    MAX_BASE_CHAIN,
    MAX_SCENE_BYTES,
    MAX_SPEED,
    MAX_YAML_DEPTH,
    MAX_YAML_NODES,
    output_stem,
)
from mech_regulator.solvers import simulate

# A small complete scene: constant J, a constant drive against a viscous load (balance at 300 rad/s), RK45.
PLAIN = """\
name: plain
machine:
  inertia: 0.5
  drive: {type: constant, torque: 3.0}
  loads:
    - {type: viscous, coefficient: 0.01}
scenario:
  initial: {phi: 0.0, omega: 10.0}
  duration: 2.0
solver: {method: RK45, rtol: 1.0e-6, sample_rate: 100.0}
"""

# "Billion laughs": nine levels of nine aliases, 9^9 values once expanded, about 600 bytes of text.
BOMB_ANCHORS = "".join(f"x{level}: &{level} [" + ", ".join([f"*{level - 1}"] * 9) + "]\n" for level in range(1, 10))
BOMB = "x0: &0 lol\n" + BOMB_ANCHORS


@pytest.fixture
def composed(monkeypatch) -> list[int]:
    """Counts the YAML nodes the scene loader composes (the work of reading)."""
    count = [0]
    compose = loading._Loader.compose_node

    def counting(self, parent, index):
        count[0] += 1
        return compose(self, parent, index)

    monkeypatch.setattr(loading._Loader, "compose_node", counting)
    return count


@pytest.fixture
def evaluations(monkeypatch) -> list[int]:
    """Counts the evaluations of every right-hand side (and crank_side) the models build (the work of running)."""
    count = [0]
    build = MachineModel._right_hand_side

    def counting(self, *args, **kwargs):
        function = build(self, *args, **kwargs)

        def counted(*arguments):
            count[0] += 1
            return function(*arguments)

        return counted

    monkeypatch.setattr(MachineModel, "_right_hand_side", counting)
    return count


def refused(capsys, *argv: str, command: str = "simulate") -> str:
    """Run the command line (run_cli fails on a traceback); assert exit code 2 and nothing on stdout; the message (a
    'note:' line announcing a first compilation, on a machine that has not compiled it yet, left out)."""
    code, out, err = run_cli(capsys, command, *argv)
    assert code == 2, (code, out, err)
    message = "".join(line for line in err.splitlines(keepends=True) if not line.startswith("note: compiling"))
    assert out == "" and message.startswith("mech-regulator: "), err
    return message


def plain(tmp_path: Path, text: str = PLAIN, name: str = "plain.yaml") -> str:
    return str(write_scene(tmp_path, text, name))


# ----------------------------------------------------------------------------------------------
# Reading: alias bombs, deep nesting, size


@pytest.mark.parametrize("where", ["machine.inertia", "scenario.duration", "name", "top level key"])
def test_alias_bomb_in_any_value_is_refused_while_reading(tmp_path, capsys, composed, where):
    keys = {
        "machine.inertia": "machine: {inertia: *9}\nscenario: {duration: 1.0}\n",
        "scenario.duration": "machine: {inertia: 1.0}\nscenario: {duration: *9}\n",
        "name": "name: *9\nmachine: {inertia: 1.0}\nscenario: {duration: 1.0}\n",
        "top level key": "machine: {inertia: 1.0}\nscenario: {duration: 1.0}\nlaughs: *9\n",
    }
    path = plain(tmp_path, BOMB + keys[where], "bomb.yaml")
    err = refused(capsys, path, command="describe")
    assert "aliases expanded" in err and str(MAX_YAML_NODES) in err and "line 7" in err, err
    assert composed[0] < 200  # the bomb's ~100 nodes as written, never its 9^9 expanded values
    assert len(err) < 1000


def test_alias_bomb_in_an_override(capsys, composed):
    bomb = "[" + ", ".join(["&a [" + ", ".join(["x"] * 600) + "]"] + ["*a"] * 600) + "]"
    err = refused(capsys, "lathe", "--set", f"machine.loads={bomb}", command="describe")
    assert err.startswith("mech-regulator: --set machine.loads: refused") and "aliases expanded" in err, err
    assert composed[0] < 2000 + 100  # the lathe and the override as written


def test_a_recursive_alias_is_refused(tmp_path, capsys, composed):
    err = refused(capsys, plain(tmp_path, PLAIN + "laughs: &a [1, *a]\n"), command="describe")
    assert "recursive" in err and "*a" in err, err
    assert composed[0] < 60  # the scene as written


@pytest.mark.parametrize(
    "text",
    [
        "machine: " + "[" * 100_000 + "]" * 100_000 + "\n",
        "machine:\n" + "".join("  " * level + f"k{level}:\n" for level in range(1, 200)),
    ],
)
def test_deep_nesting_is_refused_at_the_limit(tmp_path, capsys, composed, text):
    err = refused(capsys, plain(tmp_path, text, "deep.yaml"), command="describe")
    assert f"nested deeper than {MAX_YAML_DEPTH} levels" in err, err
    assert composed[0] <= 2 * MAX_YAML_DEPTH + 5  # a key and a value per level of a mapping


def test_nesting_that_aliases_make_deep_is_refused(tmp_path, capsys, composed):
    chain = "a0: &a0 [1]\n" + "".join(f"a{k}: &a{k} [[[[[*a{k - 1}]]]]]\n" for k in range(1, 12))
    err = refused(capsys, plain(tmp_path, chain + "machine: {inertia: *a11}\n"), command="describe")
    assert f"nest deeper than {MAX_YAML_DEPTH} levels" in err, err
    assert composed[0] < 100


def test_a_file_beyond_the_size_limit_is_refused(tmp_path, capsys):
    path = plain(tmp_path, PLAIN + "description: " + "x" * MAX_SCENE_BYTES + "\n", "big.yaml")
    err = refused(capsys, path, command="describe")
    assert f"larger than {MAX_SCENE_BYTES} bytes" in err, err


def test_python_tags_are_refused(capsys):
    err = refused(capsys, "lathe", "--set", "name=!!python/object/apply:os.system [echo hi]", command="describe")
    assert "--set name" in err and "could not determine a constructor" in err, err


# ----------------------------------------------------------------------------------------------
# Numbers that make a run impossible: refused before it starts, naming the key, the value and what is allowed


@pytest.mark.parametrize(
    "overrides, fragments",
    [
        (
            ["solver.method=RK4", "solver.step=1e-300"],
            ["solver.step = 1e-300 s would take 2e+300 steps for 2 s", "solver.step >= 2e-07 s"],
        ),
        (["solver.max_step=1e-300"], ["solver.max_step = 1e-300 s would take at least 2e+300 steps"]),
        (
            ["solver.method=energy", "solver.phi_step_deg=1e-300"],
            ["solver.phi_step_deg = 1e-300 deg would take 3.6e+302 steps per turn"],
        ),
        (
            ["solver.method=energy", "solver.phi_step_deg=1e-4"],
            ["solver.phi_step_deg = 0.0001 deg", "initial speed 10"],
        ),
        (
            ["solver.method=energy", "solver.phi_step_deg=5e-5", "scenario.initial.omega=0"],
            ["solver.phi_step_deg = 5e-05 deg would take about 1.4e+07 steps", "the crank turns some 12 rad"],
        ),
        (
            ["solver.sample_rate=1e12"],
            ["solver.sample_rate = 1e+12 Hz gives 2e+12 output samples", "solver.sample_rate <= 1e+07 Hz"],
        ),
        (
            ["machine.flywheel={inertia: 1.0, ratio: 1e200}"],
            ["machine.flywheel.ratio = 1e+200: beyond the limit", "1e+15"],
        ),
        (["machine.drive.torque=1e150"], ["machine.drive.torque = 1e+150: beyond the limit"]),
        ([f"machine.inertia={10**400}"], ["machine.inertia = 1000000000", "..."]),
        (["scenario.duration=1e9"], ["scenario.duration = 1e+09 s: longer than the limit of 1e+07 s"]),
        (["scenario.initial.omega=2e6"], ["scenario.initial.omega = 2e+06 rad/s: beyond the limit of 1e+06 rad/s"]),
        (["machine.inertia=1e-300"], ["machine.inertia = 1e-300 kg m^2", "below the limit of 1e-12 kg m^2"]),
        (["machine.loads=[{type: fan, coefficient: 1e14}]"], ["solver.method = RK45", "Radau or BDF"]),
    ],
)
def test_impossible_numbers_are_refused_up_front(tmp_path, capsys, evaluations, overrides, fragments):
    err = refused(capsys, plain(tmp_path), "--quiet", *[part for item in overrides for part in ("--set", item)])
    for fragment in fragments:
        assert fragment in err, (fragment, err)
    assert evaluations[0] <= 50  # at most the few evaluations of the refusal's own estimate; no step


def test_a_stiff_governor_is_refused_for_an_explicit_method(capsys, evaluations):
    err = refused(
        capsys,
        "engine_indirect_rigid",
        "--quiet",
        "--set",
        "governor.servo.gain=1e15",
        "--set",
        "scenario.load_events=[]",
        "--set",
        "scenario.duration=1",
    )
    assert "solver.method = DOP853" in err and "state servo (governor.servo.gain" in err, err
    assert evaluations[0] <= 200


def test_an_exchange_step_that_would_take_too_many_exchanges(capsys, evaluations):
    err = refused(capsys, "engine_direct", "--quiet", "--exchange-step", "1e-6")
    assert "--exchange-step 1e-06 s would take 1.6e+07 exchanges for 16 s" in err, err
    assert evaluations[0] <= 200


@pytest.mark.parametrize("command", ["simulate", "run"])
@pytest.mark.parametrize("trip", ["-1", "nan", "inf"])
def test_an_overspeed_trip_that_is_not_a_speed(capsys, tmp_path, command, trip):
    """Refused before anything runs (no node started: run's output folder stays empty)."""
    extra = ["--exchange-step", "0.01"] if command == "simulate" else ["--out", str(tmp_path / "run.rrd")]
    err = refused(capsys, "lathe", "--quiet", *extra, "--overspeed-trip", trip, command=command)
    assert f"--overspeed-trip {float(trip):g}: expected a speed >= 0 rad/s (0: none)" in err, err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("command", ["simulate", "run"])
@pytest.mark.parametrize("tolerance", ["0", "-0.5", "nan", "2"])
def test_an_exchange_tolerance_that_is_not_a_relative_error(capsys, tmp_path, command, tolerance):
    """Refused before anything runs (no node started: run's output folder stays empty)."""
    extra = ["--exchange-step", "0.01"] if command == "simulate" else ["--out", str(tmp_path / "run.rrd")]
    err = refused(
        capsys,
        "lathe",
        "--quiet",
        "--set",
        "solver.path=reference",
        *extra,
        "--exchange-tolerance",
        tolerance,
        command=command,
    )
    assert f"--exchange-tolerance {float(tolerance):g}: expected a relative error between 0 and 1" in err, err
    assert list(tmp_path.iterdir()) == []


def test_an_exchange_tolerance_without_the_exchanges_or_the_coupling_it_needs(capsys):
    err = refused(capsys, "lathe", "--quiet", "--exchange-tolerance", "1e-6")
    assert "--exchange-tolerance 1e-06: the adaptive step is the co-simulation's; expected --exchange-step H" in err
    err = refused(
        capsys, "lathe", "--quiet", "--exchange-step", "0.01", "--coupling", "hold", "--exchange-tolerance", "1e-6"
    )
    assert "--exchange-tolerance 1e-06 with --coupling hold" in err and "expected --coupling corrected" in err, err


def test_an_overspeed_trip_without_the_exchanges_it_acts_at(capsys):
    """simulate without --exchange-step has no trip: one asked for is refused rather than ignored."""
    err = refused(capsys, "lathe", "--quiet", "--overspeed-trip", "20")
    assert (
        "--overspeed-trip 20: the trip acts at the exchanges of the co-simulation; expected --exchange-step H" in err
    ), err


# ----------------------------------------------------------------------------------------------
# J(phi) reaching zero: refused when the model is built, with the mechanism's key values


SLIDER_ONLY = """\
machine:
  inertia: 0.0
  mechanism: {type: crank_slider, crank: 0.05, rod: 0.2, offset: 0.01, slider_mass: 2.0}
  drive: {type: constant, torque: 3.0}
scenario:
  initial: {phi: 0.3, omega: 10.0}
  duration: 2.0
"""


@pytest.mark.parametrize("overrides", [[], ["machine.inertia=1e-14"], ["solver.method=energy"], ["solver.path=fast"]])
def test_inertia_reaching_zero_is_refused(tmp_path, capsys, evaluations, overrides):
    err = refused(capsys, plain(tmp_path, SLIDER_ONLY), "--quiet", *[p for item in overrides for p in ("--set", item)])
    for fragment in (
        "the reduced inertia J(phi) falls to",
        "type crank_slider: crank 0.05, rod 0.2, offset 0.01",
        "slider_mass 2",
        "give machine.inertia > 0",
    ):
        assert fragment in err, (fragment, err)
    assert evaluations[0] == 0


def test_four_bar_with_only_a_rocker_inertia_is_refused():
    with pytest.raises(SceneError, match="reduced inertia J.phi. falls to .* type four_bar"):
        build_model(
            load_scene(
                "four_bar_rocker",
                [
                    "machine.inertia=0",
                    "machine.flywheel=null",
                    "machine.mechanism.crank_mass=0",
                    "machine.mechanism.coupler_mass=0",
                    "machine.mechanism.coupler_inertia=0",
                    "machine.mechanism.rocker_mass=0",
                ],
            )
        )


# ----------------------------------------------------------------------------------------------
# Blow-ups: the run stops at once, status failed, with the time, the state and the likely cause


@pytest.mark.parametrize("method", ["RK45", "DOP853", "RK4"])
def test_a_blow_up_stops_the_run_at_once_and_keeps_it(tmp_path, capsys, method):
    overrides = ["machine.drive.torque=1e14", f"solver.method={method}"]
    code, out, err = run_cli(
        capsys,
        "simulate",
        plain(tmp_path),
        "--quiet",
        "--json",
        "--out",
        str(tmp_path / "run.csv"),
        *[p for item in overrides for p in ("--set", item)],
    )
    assert code == 1, err
    summary = json.loads(out)
    assert summary["status"] == "failed"
    message = summary["message"]
    for fragment in (
        f"{method}: the run blew up at t = ",
        "omega = ",
        f"is beyond {MAX_SPEED:g} rad/s",
        "the state: phi = ",
        "likely cause: the crank's net moment 1e+14 N m on J = 0.5 kg m^2",
    ):
        assert fragment in message, (fragment, message)
    assert message in err
    assert summary["solver"]["steps"] <= 50  # it stops at the first step beyond the bound
    assert abs(summary["omega_end"]) > MAX_SPEED  # the step that carried it there is kept...
    assert (tmp_path / "run.csv").exists()  # ...and written


def test_the_energy_method_stops_at_a_blow_up_too(tmp_path):
    # (simulate refuses this scene up front: the energy method would take 2e16 steps; its own loop checks as well)
    from mech_regulator.solvers.energy_method import integrate_energy_method

    model = build_model(load_scene(plain(tmp_path), ["machine.drive.torque=1e14", "solver.method=energy"]))
    trajectory = integrate_energy_method(model)
    assert trajectory.status == "failed" and "energy: the run blew up at t = " in trajectory.message
    assert trajectory.stats.steps <= 5 and abs(trajectory(trajectory.t_end)[1]) > MAX_SPEED


@pytest.mark.parametrize("method", ["RK45", "DOP853", "RK4"])
def test_a_blow_up_stops_the_fast_path_at_the_reference_path_s_step(tmp_path, method):
    # the compiled stepper watches the speed at every step end itself: the same cut, message and step count
    overrides = ["machine.drive.torque=1e14", f"solver.method={method}"]
    reference = simulate(build_model(load_scene(plain(tmp_path), overrides)))
    fast = simulate(build_model(load_scene(plain(tmp_path), overrides + ["solver.path=fast"])))
    assert reference.status == fast.status == "failed" and fast.message == reference.message
    assert fast.stats.steps == reference.stats.steps <= 50
    assert fast.t_end == pytest.approx(reference.t_end, rel=1e-12)
    assert (
        abs(fast(fast.t_end)[1])
        > MAX_SPEED
        >= abs(fast(fast.step_ends[-1][-2] if fast.step_ends[-1].size > 1 else fast.piece_edges[-2])[1])
    )


@pytest.mark.parametrize("path", ["reference", "fast"])
def test_an_unstable_rk4_step_is_named_as_the_cause(path):
    scene = load_scene(
        "startup", ["scenario.duration=2000", "solver.method=RK4", "solver.step=1.0", f"solver.path={path}"]
    )
    trajectory = simulate(build_model(scene))
    assert trajectory.status == "failed" and trajectory.t_end == 17.0, trajectory.message
    assert "an RK4 step too long to be stable: solver.step = 1 s" in trajectory.message
    assert trajectory.stats.steps == 17


@pytest.mark.parametrize("path", ["reference", "fast"])
def test_a_run_stops_at_the_step_limit(monkeypatch, path):
    monkeypatch.setattr(time_domain, "MAX_STEPS", 40)
    trajectory = simulate(build_model(load_scene("lathe", [f"solver.path={path}"])))  # 99 steps to its end at 10 s
    assert trajectory.status == "failed" and trajectory.stats.steps == 40
    assert "after 40 steps, the limit of 40 steps for one run" in trajectory.message
    assert 0.0 < trajectory.t_end < 10.0 and np.all(np.isfinite(trajectory(trajectory.t_end)))


def test_a_co_simulated_blow_up_stops_at_the_exchange(capsys):
    code, out, err = run_cli(
        capsys,
        "simulate",
        "lathe",
        "--quiet",
        "--json",
        "--exchange-step",
        "0.01",
        "--set",
        "machine.drive.torque=1e14",
        "--set",
        "machine.loads=[]",
    )
    assert code == 1, err
    summary = json.loads(out)
    assert summary["status"] == "failed" and "the run blew up at t = " in summary["message"]
    assert summary["samples"] <= 3


# ----------------------------------------------------------------------------------------------
# Names made into file names: nothing outside the output folder


@pytest.mark.parametrize(
    "name, stem",
    [
        ("../../somewhere/evil", "somewhere_evil"),
        ("/etc/passwd", "etc_passwd"),
        ("..", "scene"),
        ("", "scene"),
        (None, "scene"),
        ("a\nb\x00c\x1b[31m", "a_b_c_31m"),
        (".hidden", "hidden"),
        ("my lathe (v2)", "my_lathe_v2_"),
        ("lathe", "lathe"),
        ("x..y", "x.y"),
        ("C:\\Windows\\evil", "C_Windows_evil"),
        ("-rf", "rf"),
        ("ü" * 5, "scene"),
    ],
)
def test_output_stem(name, stem):
    assert output_stem(name) == stem


def test_output_stem_is_short_and_never_leaves_the_folder():
    for name in ["a" * 10_000, "../" * 500, "/" * 100, "\\..\\.." * 50, ". . .", "\u2028\u202e..//"]:
        stem = output_stem(name)
        assert 0 < len(stem) <= 80 and "/" not in stem and "\\" not in stem and ".." not in stem
        assert not stem.startswith(".") and (Path("runs") / stem).resolve().parent == Path("runs").resolve()


def test_the_main_job_names_its_files_from_a_safe_name():
    recording = default_recording("../../somewhere/evil")
    assert recording.parent == Path("runs") and recording.name.startswith("somewhere_evil-")
    for suffix in (".json", ".csv", ".log", ".params.yaml"):
        assert recording.with_suffix(suffix).parent == Path("runs")


def test_a_sweep_writes_in_its_own_folder(tmp_path, monkeypatch, capsys):
    scene = plain(tmp_path, PLAIN.replace("name: plain", "name: ../../somewhere/evil").replace("2.0\n", "0.2\n"))
    work = tmp_path / "a" / "b"
    work.mkdir(parents=True)
    monkeypatch.chdir(work)
    code, _, err = run_cli(
        capsys, "sweep", scene, "--grid", "machine.inertia=0.5,1.0", "--jobs", "1", "--path", "reference", "--quiet"
    )
    assert code == 0, err
    written = sorted(str(path.relative_to(tmp_path)) for path in tmp_path.rglob("*") if path.is_file())
    assert all(path.startswith("a/b/runs/sweep-somewhere_evil/") or path == "plain.yaml" for path in written), written


# ----------------------------------------------------------------------------------------------
# base: only a scene inside the scene's own folder, or a bundled one; never the content of another file


SECRET = "db_password: hunter2\nmachine: {api_key: s3cr3t}\n"


@pytest.mark.parametrize(
    "base, fragment",
    [
        ("/etc/passwd", "not a relative path"),
        ("../outside/secret.yaml", "'..' leaves this scene's folder"),
        ("sub/../../outside/secret.yaml", "'..' leaves this scene's folder"),
        ("notes.txt", "a base file is a .yaml file"),
        ("sub/link.yaml", "a link that leads outside this scene's folder"),
        ("sub/secret.yaml", "is not a scene file"),
        ("sub/broken.yaml", "is not a valid YAML scene file"),
    ],
)
def test_base_outside_the_scene_folder_or_not_a_scene_is_refused(tmp_path, capsys, composed, base, fragment):
    write_scene(tmp_path, SECRET, "outside/secret.yaml")
    write_scene(tmp_path, SECRET, "scenes/sub/secret.yaml")
    write_scene(tmp_path, "db_password: [hunter2\n", "scenes/sub/broken.yaml")
    write_scene(tmp_path, SECRET, "scenes/notes.txt")
    (tmp_path / "scenes" / "sub" / "link.yaml").symlink_to(tmp_path / "outside" / "secret.yaml")
    path = write_scene(tmp_path, f"base: {base}\nscenario: {{duration: 1.0}}\n", "scenes/child.yaml")
    err = refused(capsys, str(path), command="describe")
    assert f"base = '{base}'" in err and fragment in err, err
    for secret in ("db_password", "hunter2", "api_key", "s3cr3t"):
        assert secret not in err, err
    assert composed[0] <= 20  # the child, and a base inside the folder (not a scene) at most


def test_base_inside_the_folder_and_bundled_still_work(tmp_path):
    write_scene(tmp_path, PLAIN, "scenes/parents/plain.yaml")
    child = write_scene(tmp_path, "base: parents/plain.yaml\nmachine: {inertia: 0.7}\n", "scenes/child.yaml")
    assert load_scene(str(child)).machine.inertia == 0.7
    assert load_scene(str(write_scene(tmp_path, "base: lathe\n", "scenes/l.yaml"))).machine.inertia == 2.0


def test_a_chain_of_bases_has_a_limit(tmp_path, capsys, composed):
    for k in range(MAX_BASE_CHAIN + 5):
        write_scene(tmp_path, f"base: s{k + 1}.yaml\n", f"s{k}.yaml")
    err = refused(capsys, str(tmp_path / "s0.yaml"), command="describe")
    assert f"a chain of more than {MAX_BASE_CHAIN} bases" in err, err
    assert composed[0] <= 3 * (MAX_BASE_CHAIN + 1)


# ----------------------------------------------------------------------------------------------
# The nodes: a bad scene_file or override ends the node with a line naming it, exit code 2


def test_the_launcher_quotes_the_reason_of_a_node():
    log = (
        "[INFO] [recorder]: recording\nmech_regulator: machine_node: scene.yaml: 1 problem:\n"
        "  solver.step = 1e-300 s would take 2e+300 steps\n[INFO] [governor]: waiting\n"
    )
    assert node_reason(log, "machine") == ": scene.yaml: 1 problem:\n  solver.step = 1e-300 s would take 2e+300 steps"
    assert node_reason(log, "governor") == ""


@pytest.mark.parametrize(
    "parameters, fragments",
    [
        (["scene_file:={bomb}"], ["machine_node: ", "aliases expanded"]),
        (["scene_file:={slider_only}"], ["machine_node: ", "reduced inertia J(phi) falls to"]),
        (
            ["scene_file:=lathe", "overrides:=[solver.method=RK4,solver.step=1e-300]"],
            ["machine_node: ", "solver.step = 1e-300 s would take"],
        ),
    ],
)
def test_a_node_ends_with_a_message_on_a_hostile_scene(tmp_path, parameters, fragments):
    pytest.importorskip("rclpy")
    from ros_support import next_domain_id, ros_environment

    files = {
        "bomb": plain(tmp_path, BOMB + "machine: {inertia: *9}\nscenario: {duration: 1.0}\n", "bomb.yaml"),
        "slider_only": plain(tmp_path, SLIDER_ONLY, "slider_only.yaml"),
    }
    arguments = [part for parameter in parameters for part in ("-p", parameter.format(**files))]
    done = subprocess.run(
        [sys.executable, "-m", "mech_regulator.nodes.machine", "--ros-args", *arguments],
        capture_output=True,
        text=True,
        timeout=120,
        env=ros_environment(next_domain_id()),
    )
    output = done.stdout + done.stderr
    assert done.returncode == 2, output
    assert "Traceback" not in output
    for fragment in fragments:
        assert fragment in output, (fragment, output)
