"""A general linkage in a scene (`machine.mechanism: {type: linkage, ...}`, docs/linkages.md): validation messages, the
`structure` command, `kinematics` and `simulate` on the reference path, and the bundled shaper.

The four-bar of the bundled four_bar_rocker scene written as a linkage runs as the four_bar does: the same reduced
inertia and weight, the rocker loads on the linkage's output link, so the same speed to the integration's accuracy
(both at rtol 1e-9; a wrong term of J, dJ/dphi, the weight or the output ratio changes it by far more than 1e-6).
The linkage counts the crank's m cg^2 in J(phi); the four_bar leaves it to machine.inertia, so machine.inertia of
the linkage scene is smaller by that much."""

from __future__ import annotations

import copy
import json
import re

import numpy as np
import pytest
from support import run_cli

from mech_regulator.analysis.kinematics import kinematics_table, reactions_table
from mech_regulator.cli.main import main
from mech_regulator.mechanisms import build_reduced
from mech_regulator.mechanisms.checks import refuse_unbuildable
from mech_regulator.model import build_model
from mech_regulator.scene import SceneError, load_scene, validate_scene
from mech_regulator.solvers import simulate
from mech_regulator.solvers.compiled import fast_path_refusal

FOUR_BAR_LINKAGE = {
    "type": "linkage",
    "frame": {"A": [0.0, 0.0], "D": [0.10, 0.0]},
    "crank": "crank",
    "links": {
        "crank": {"points": {"A": [0.0, 0.0], "B": [0.04, 0.0]}, "mass": 0.2, "centre": [0.02, 0.0]},
        "coupler": {
            "points": {"B": [0.0, 0.0], "C": [0.12, 0.0]},
            "mass": 0.5,
            "centre": [0.06, 0.0],
            "inertia": 6.0e-4,
        },
        "rocker": {
            "points": {"D": [0.0, 0.0], "C": [0.08, 0.0]},
            "mass": 0.4,
            "centre": [0.04, 0.0],
            "inertia": 2.1e-4,
        },
    },
    "joints": {
        "A": {"type": "revolute", "links": ["frame", "crank"]},
        "B": {"type": "revolute", "links": ["crank", "coupler"]},
        "C": {"type": "revolute", "links": ["coupler", "rocker"]},
        "D": {"type": "revolute", "links": ["frame", "rocker"]},
    },
    "output": {"link": "rocker"},
}


def as_linkage(scene_name: str = "four_bar_rocker", mechanism: dict | None = None) -> dict:
    """The bundled four_bar_rocker scene (as data) with its four-bar replaced by the same linkage and its machine
    inertia lowered by the crank's m cg^2 = 0.2 * 0.02^2."""
    data = load_scene(scene_name).model_dump(exclude_none=True)
    data["machine"]["mechanism"] = copy.deepcopy(mechanism or FOUR_BAR_LINKAGE)
    data["machine"]["inertia"] -= 0.2 * 0.02**2
    return data


def refusal(data: dict) -> str:
    """The message refusing a scene: its format when read, or its mechanism's checks (mechanisms/checks.py)."""
    with pytest.raises(SceneError) as error:
        refuse_unbuildable(validate_scene(data))
    return str(error.value)


def test_four_bar_as_a_linkage_runs_as_the_four_bar():
    overrides = ["scenario.duration=0.6", "solver.path=reference"]
    reference = build_model(load_scene("four_bar_rocker", overrides))
    linkage = build_model(
        validate_scene(as_linkage()).model_copy(
            update={"scenario": reference.scene.scenario, "solver": reference.scene.solver}
        )
    )
    first, second = simulate(reference), simulate(linkage)
    times = np.linspace(0.0, 0.6, 61)
    omega_four_bar, omega_linkage = first(times)[1], second(times)[1]
    assert np.max(np.abs(omega_linkage - omega_four_bar)) < 1e-6 * np.max(np.abs(omega_four_bar))
    assert np.ptp(omega_four_bar) > 1.0  # the run is not trivial: the machine speeds up from rest


def test_four_bar_as_a_linkage_has_the_four_bars_kinematics():
    four_bar = kinematics_table(load_scene("four_bar_rocker").machine.mechanism, 10.0, 37)
    linkage = kinematics_table(validate_scene(as_linkage()).machine.mechanism, 10.0, 37)
    for key in ("B_x", "B_vy", "C_x", "C_y", "C_vx", "C_ay", "C_a"):
        assert linkage[key] == pytest.approx(four_bar[key], rel=1e-12, abs=1e-14)


@pytest.mark.parametrize(
    "change, expected",
    [
        (lambda m: m["joints"]["D"].update(links=["frame", "rocket"]), "joint 'D' names the link 'rocket'"),
        (lambda m: m["joints"].pop("D"), r"W = 3\*3 - \(2\*3 \+ 0 - 0 - 0\) - 0 = 3; expected W = 1"),
        (lambda m: m["links"]["rocker"]["points"].pop("C"), "needs the point 'C' on the link 'rocker'"),
        (
            lambda m: m["links"]["crank"]["points"].update(B=[0.07, 0.0]),
            r"RRR group C \(links coupler, rocker\) fails for crank angles 342 to 378 deg \(checked every 0.5 deg; at "
            r"0.000 deg cannot be assembled: the distance 0.03 m between B and D is outside \[0.04, 0.2\] m\)",
        ),
        (
            lambda m: m["links"]["coupler"]["points"].update(C=[0.0, 0.0]),
            r"the link coupler of the RRR group C has its joints B and C at one point \[0, 0\] m",
        ),
        (
            lambda m: m.update(branches={"B": -1}),
            r"branches names \['B'\], which are not the internal joint of a group "
            r"with two assemblies \(RRR, RRP, RPR; PRP and RPP have one\); "
            r"expected some of \['C'\]",
        ),
        (
            lambda m: m.update(crank="rocker"),
            r"RRR group B \(links crank, coupler\) fails for crank angles 129 to 231 deg, "
            r"305.5 to 414.5 deg",
        ),
        (lambda m: m["links"].update(frame={"points": {"A": [0.0, 0.0]}}), "links has a link named 'frame'"),
    ],
)
def test_bad_linkages_are_refused_with_what_was_found(change, expected):
    mechanism = copy.deepcopy(FOUR_BAR_LINKAGE)
    change(mechanism)
    assert re.search(expected, refusal(as_linkage(mechanism=mechanism)))


def test_output_loads_need_the_linkages_output():
    data = as_linkage()
    del data["machine"]["mechanism"]["output"]
    assert (
        "loads[0] type 'rocker_viscous' acts on the rocker: the linkage needs mechanism.output.link (it has no "
        "output)" in refusal(data)
    )
    data["machine"]["mechanism"]["output"] = {"link": "rocker"}
    data["machine"]["loads"] = [{"type": "slider_viscous", "coefficient": 1.0}]
    assert "mechanism.output.joint (a prismatic joint)" in refusal(data)


def test_structure_command_prints_the_groups_and_draws_them(tmp_path, capsys):
    plot = tmp_path / "shaper_structure.png"
    assert main(["structure", "shaper", "--plot", str(plot)]) == 0
    out = capsys.readouterr().out
    assert "W = 3*5 - (2*7 + 0 - 0 - 0) - 0 = 1" in out
    assert "group 1: class II, type RPR, links block + lever" in out
    assert "group 2: class II, type RRP, links link + ram" in out
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["structure", "shaper", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert (summary["n"], summary["p5"], summary["p4"], summary["W"]) == (5, 7, 0, 1)
    assert [group["type"] for group in summary["groups"]] == ["RPR", "RRP"]


def test_structure_command_refuses_what_it_cannot_analyse(tmp_path, capsys):
    assert main(["structure", "four_bar_rocker"]) == 2
    assert "structure analyses machine.mechanism.type: linkage" in capsys.readouterr().err
    data = load_scene("shaper").model_dump(exclude_none=True)
    del data["machine"]["mechanism"]["joints"]["G"], data["machine"]["mechanism"]["output"]
    data["machine"]["loads"] = data["machine"]["loads"][1:]  # the ram's guide is gone, and its load with it
    path = tmp_path / "free_ram.yaml"
    path.write_text(json.dumps(data), encoding="utf-8")
    assert main(["structure", str(path)]) == 2
    err = capsys.readouterr().err
    assert "the linkage has W = 3*5 - (2*6 + 0 - 0 - 0) - 0 = 3; expected W = 1" in err, err
    assert "Traceback" not in err


def test_the_shaper_runs_on_the_reference_path_and_the_fast_path_takes_it():
    assert fast_path_refusal(load_scene("shaper")) is None  # compiled too (test/test_linkage_flat.py)
    model = build_model(load_scene("shaper", ["scenario.duration=0.3", "solver.path=reference"]))
    trajectory = simulate(model)
    times = np.linspace(0.0, 0.3, 31)
    columns = model.columns(times, trajectory(times))
    assert columns["omega"][-1] > 5.0 and np.all(np.isfinite(columns["J"]))
    # the ram's x (the output joint G) within the travel `kinematics shaper` gives, 0.0069977 to 0.37365 m
    assert np.all((columns["x_output"] > 0.0069) & (columns["x_output"] < 0.3737))
    assert np.ptp(columns["x_output"]) > 0.1 and np.all(np.isfinite(columns["v_output"]))


def test_the_walking_beam_linkage_scene_reproduces_the_walking_beam_scene():
    """The bundled walking_beam_linkage (source 004's eight-bar written as links and joints, its output x_C read by
    a massless Scotch yoke) has the walking_beam's J (plus the crank's m cg^2 = 1.0 * 0.03^2, which its
    machine.inertia leaves out), dJ/dphi, weight moment and output to 1e-12, and its run (slider_viscous on the
    yoke for the walking_beam's shuttle_viscous) the walking_beam's speed to 1e-9 of its range (both on the reference
    path at rtol 1e-9, whose step sequences the 1e-15 differences of J do not change)."""
    from mech_regulator.mechanisms import build_reduced

    gravity = (0.0, -9.81)
    linkage = build_reduced(load_scene("walking_beam_linkage").machine.mechanism, gravity)
    preset = build_reduced(load_scene("walking_beam").machine.mechanism, gravity)
    for phi in np.linspace(0.0, 2.0 * np.pi, 25)[:-1] + 0.05:
        (J, dJ, weight, q, dq), (J0, dJ0, weight0, x_C, dx_C) = linkage(phi), preset(phi)
        assert J - 1.0 * 0.03**2 == pytest.approx(J0, rel=1e-12)
        assert (dJ, q, dq) == pytest.approx((dJ0, x_C, dx_C), abs=1e-12)
        assert weight == pytest.approx(weight0, abs=1e-12 * 10.0 * 9.81)
    overrides = ["scenario.duration=0.4", "solver.path=reference"]
    first = build_model(load_scene("walking_beam", overrides))
    second = build_model(load_scene("walking_beam_linkage", overrides))
    assert second.inertia_constant == pytest.approx(first.inertia_constant - 0.0009, abs=1e-15)
    times = np.linspace(0.0, 0.4, 41)
    omega_preset, omega_linkage = simulate(first)(times)[1], simulate(second)(times)[1]
    assert np.ptp(omega_preset) > 0.2  # the speed swings: the comparison is not of constants
    assert np.max(np.abs(omega_linkage - omega_preset)) < 1e-9 * np.ptp(omega_preset)


def test_the_sieve_shaker_gives_source_001s_velocities_and_accelerations():
    """Source 001, chapter II, exercise 3: at 20 rad/s with AB and CD upright and BC level (phi = 90 deg), its
    velocity and acceleration polygons give v_C = v_B = 2 m/s, a_C = a_C^n = 2^2/0.2 = 20 m/s^2, E the middle of CD:
    v_E = 1 m/s, a_E = 10 m/s^2, and the sieve v_F = 1 m/s, a_F = 5 m/s^2 (the guide's height was chosen for
    the last one: the source does not give it)."""
    table = kinematics_table(load_scene("sieve_shaker").machine.mechanism, 20.0, 5)  # 0, 90, 180, 270, 360 deg
    expected = {
        "B_v": 2.0,
        "B_a": 40.0,
        "C_v": 2.0,
        "C_a": 20.0,
        "E_v": 1.0,
        "E_a": 10.0,
        "F_v": 1.0,
        "F_a": 5.0,
        "C_x": 0.2,
        "C_y": 0.1,
        "E_x": 0.2,
        "E_y": 0.0,
    }
    assert {key: table[key][1] for key in expected} == pytest.approx(expected, abs=1e-12)


def test_the_six_bar_press_table_is_its_pressing_force_reduced_to_the_crank():
    """The six_bar_press's table load is 40 kN x dq/dphi (q the ram's travel downwards) at its points inside the
    last 20 mm of the down stroke before the bottom dead centre, 0 outside (to the table's 0.1 N m rounding)."""
    from mech_regulator.mechanisms import build_reduced

    machine = load_scene("six_bar_press").machine
    reduced = build_reduced(machine.mechanism, None)
    bottom = max(reduced(phi)[3] for phi in np.radians(np.arange(0.0, 360.0, 0.25)))
    assert bottom == pytest.approx(reduced(np.radians(24.0))[3], abs=1e-6)  # the bottom dead centre near 24 deg
    table = machine.loads[2]
    for angle, torque in zip(table.angle_deg, table.torque):
        _, _, _, q, dq = reduced(np.radians(angle))
        pressing = q >= bottom - 0.02 and dq > 0.0
        assert torque == pytest.approx(40e3 * dq if pressing else 0.0, abs=0.05), angle


@pytest.mark.parametrize("name", ["six_bar_press", "four_bar_rocker", "crank_slider_bench"])
def test_kinematics_gives_the_reactions_and_a_balancing_moment_that_keeps_the_speed(tmp_path, capsys, name):
    """`kinematics` adds the kinetostatics at constant speed: R_<joint> [N] and M_balancing [N m] columns, a summary
    and a fourth panel. Oracle: at constant omega the balancing moment is what the reduced model needs,
    M_b = 1/2 J'(phi) omega^2 - M_weight(phi) (mechanisms.build_reduced), computed group by group from the
    reactions instead."""
    scene = load_scene(name)
    mechanism, gravity = scene.machine.mechanism, tuple(scene.machine.gravity or (0.0, 0.0))
    columns = reactions_table(mechanism, gravity, 7.0, np.linspace(0.0, 2.0 * np.pi, 13))
    reduced = build_reduced(mechanism, gravity)
    expected = [0.5 * reduced(phi)[1] * 7.0**2 - reduced(phi)[2] for phi in np.linspace(0.0, 2.0 * np.pi, 13)]
    scale = np.max(np.abs(expected))
    assert scale > 0.0 and np.max(np.abs(columns["M_balancing"] - expected)) <= 1e-9 * scale
    assert all(np.all(columns[key] >= 0.0) and np.any(columns[key] > 0.0) for key in columns if key.startswith("R_"))
    out, plot = tmp_path / "k.csv", tmp_path / "k.png"
    code, stdout, err = run_cli(
        capsys, "kinematics", name, "--points", "13", "--omega", "7", "--out", str(out), "--plot", str(plot)
    )
    assert code == 0, err
    assert "balancing moment on the crank" in stdout and plot.stat().st_size > 0
    header = out.read_text().splitlines()[0].split(",")
    assert "M_balancing" in header and sum(column.startswith("R_") for column in header) >= 4
