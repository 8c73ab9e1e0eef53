"""Tests of the eight-bar walking-beam transport mechanism (source 004, mechanisms/walking_beam.py), its scene
type, the `kinematics` command and the shuttle loads.

Independent references: the loop closure `a e^{i phi} + b e^{i th3} - d e^{i th1} - c e^{i th4} = 0` solved with
scipy.optimize.fsolve at every crank angle (continuation from the previous angle), the points built from those
angles, velocities and accelerations by central differences of the fsolve positions, the reduced inertia by its
definition from those numerical velocities, the weight moment as -dV/dphi, and energy conservation in a run.

Tolerances: fsolve converges to ~1e-13 rad here; a central difference with step h has truncation error
h^2/6 |P'''| (|P'''| < ~5 m/rad^3 for this 0.1 m crank) and rounding ~1e-13 / h, so 1e-7 (h = 1e-4, first
derivative) and 1e-5 (h = 1e-3, second derivative) leave margins of 10 or more while a wrong sign or factor
changes values of order 0.1.
"""

from __future__ import annotations

import cmath
import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import fsolve
from support import model_of, preset_reduced, run_cli, scene, simulate_complete, write_scene

from mech_regulator.analysis.kinematics import kinematics_table
from mech_regulator.mechanisms import walking_beam
from mech_regulator.mechanisms.drawing import mechanism_outline
from mech_regulator.scene.loading import read_scene_data

TWO_PI = 2.0 * math.pi
OMEGA = 10.0  # the paper's crank speed [rad/s]
SCENES = Path(__file__).resolve().parents[1] / "config" / "scenes"
SCENE = read_scene_data(SCENES / "walking_beam.yaml")
SPEC = model_of(SCENE).scene.machine.mechanism
GEOMETRY = walking_beam.geometry_from_scene(SPEC)
ANGLES = np.linspace(0.0, TWO_PI, 37)[:-1] + 0.013


def loop_closure_points(phi: float, guess: tuple[float, float]) -> tuple[dict[str, complex], tuple[float, float]]:
    """Points A, B, C, D, E (complex, m) from th3, th4 solving the loop closure with fsolve near guess."""
    g = GEOMETRY
    O2 = g.frame * cmath.exp(1j * g.frame_angle)

    def residual(angles):
        th3, th4 = angles
        gap = g.crank * cmath.exp(1j * phi) + g.coupler * cmath.exp(1j * th3) - O2 - g.rocker * cmath.exp(1j * th4)
        return [gap.real, gap.imag]

    (th3, th4), info, flag, message = fsolve(residual, guess, xtol=1e-14, full_output=True)
    assert max(abs(value) for value in residual((th3, th4))) < 1e-15, message  # at round-off: converged
    A = g.crank * cmath.exp(1j * phi)
    B = O2 + g.rocker * cmath.exp(1j * th4)
    C = A + g.coupler_point * cmath.exp(1j * (th3 + g.coupler_point_angle))
    s = g.beam_length * cmath.exp(1j * g.beam_angle)
    return {"A": A, "B": B, "C": C, "D": C + s, "E": B + s, "th3": th3, "th4": th4}, (th3, th4)


@pytest.fixture(scope="module")
def numerical():
    """fsolve positions at phi and phi +- h, phi +- 2h for each angle, by continuation around the turn.
    Returns {phi: {offset: points}} with offsets in units of the steps below."""
    # Start on the scene's branch from a rough guess (the closed form rounded to 0.3 rad): fsolve does the rest.
    angles0 = walking_beam.solve(ANGLES[0], GEOMETRY)[0]
    guess = (round(angles0[0] / 0.3) * 0.3, round(angles0[3] / 0.3) * 0.3)
    table = {}
    for phi in ANGLES:
        points, guess = loop_closure_points(phi, guess)
        entry = {0.0: points}
        for step in (1e-4, -1e-4, 1e-3, -1e-3):
            entry[step] = loop_closure_points(phi + step, guess)[0]
        table[phi] = entry
    return table


def first_difference(entry, key, h=1e-4):
    return (entry[h][key] - entry[-h][key]) / (2.0 * h)


def second_difference(entry, key, h=1e-3):
    return (entry[h][key] - 2.0 * entry[0.0][key] + entry[-h][key]) / (h * h)


# ----------------------------------------------------------------------------------------------
# Closed form against the independent loop closure


def test_positions_match_fsolve_of_the_loop_closure(numerical):
    for phi, entry in numerical.items():
        closed = walking_beam.solve(phi, GEOMETRY)[1]
        for name in "ABCDE":
            assert abs(closed[name][0] - entry[0.0][name]) < 1e-11, (name, phi)


def test_velocity_and_acceleration_ratios_match_differences_of_fsolve_positions(numerical):
    for phi, entry in numerical.items():
        closed = walking_beam.solve(phi, GEOMETRY)[1]
        for name in "ABCDE":
            assert abs(closed[name][1] - first_difference(entry, name)) < 1e-7, (name, phi)
            assert abs(closed[name][2] - second_difference(entry, name)) < 1e-5, (name, phi)


def test_parallelograms_keep_the_shuttle_bar_and_tie_translating():
    """D - C and E - B stay the beam vector s (the shuttle bar and the tie never turn), O3E stays parallel to
    O2B and the side link ED parallel and equal to BC, at every angle."""
    g = GEOMETRY
    s = g.beam_length * cmath.exp(1j * g.beam_angle)
    O2 = g.frame * cmath.exp(1j * g.frame_angle)
    for phi in ANGLES:
        points = {name: motion[0] for name, motion in walking_beam.solve(phi, g)[1].items()}
        assert abs(points["D"] - points["C"] - s) < 1e-15 and abs(points["E"] - points["B"] - s) < 1e-15
        assert abs((points["E"] - (O2 + s)) - (points["B"] - O2)) < 1e-15
        assert abs((points["D"] - points["E"]) - (points["C"] - points["B"])) < 1e-15
        assert abs(abs(points["C"] - points["B"]) - abs(walking_beam.side(g))) < 1e-12
        assert abs(points["B"] - O2) == pytest.approx(g.rocker, abs=1e-12)
        assert abs(points["B"] - points["A"]) == pytest.approx(g.coupler, abs=1e-12)


# ----------------------------------------------------------------------------------------------
# Source 004's figures at omega = 10 rad/s (the OCR keeps only the axes of figures 5-7; see docs/linkages.md)


@pytest.fixture(scope="module")
def paper_table():
    return kinematics_table(SPEC, OMEGA, 721)


def test_crank_pin_speed_and_acceleration_are_the_papers_constants(paper_table):
    """Figures 6a and 7a: A turns uniformly, v_A = a omega = 1000 mm/s and a_A = a omega^2 = 10^4 mm/s^2."""
    assert paper_table["A_v"] == pytest.approx(np.full(721, 1.0), abs=1e-12)
    assert paper_table["A_a"] == pytest.approx(np.full(721, 10.0), abs=1e-11)
    assert np.hypot(paper_table["A_x"], paper_table["A_y"]) == pytest.approx(np.full(721, 0.1), abs=1e-15)


def test_coupler_curve_fills_the_axes_of_figure_5c(paper_table):
    """Figure 5c's axes (x 200..450 mm by 50, y -120..40 mm by 20) hold the path of C, which reaches past the
    next tighter ticks (Matlab's automatic limits): 200 <= x_min < 250, 400 < x_max <= 450, -120 <= y_min < -100,
    20 < y_max <= 40 [mm]."""
    x, y = paper_table["C_x"] * 1e3, paper_table["C_y"] * 1e3
    assert 200.0 <= x.min() < 250.0 and 400.0 < x.max() <= 450.0
    assert -120.0 <= y.min() < -100.0 and 20.0 < y.max() <= 40.0


def test_point_pairs_have_the_same_velocity_and_acceleration(paper_table):
    """Figures 6b,c and 7b,c plot B with E and C with D: one curve each (to rounding: E and D are placed on their own
    links, the parallelograms' groups)."""
    for first, second in (("B", "E"), ("C", "D")):
        for key in ("vx", "vy", "ax", "ay"):
            scale = np.abs(paper_table[f"{first}_{key}"]).max()
            assert np.abs(paper_table[f"{first}_{key}"] - paper_table[f"{second}_{key}"]).max() <= 1e-12 * scale
    assert not np.allclose(paper_table["B_v"], paper_table["C_v"])


def test_velocities_scale_with_omega_and_accelerations_with_its_square():
    slow, fast = kinematics_table(SPEC, 1.0, 19), kinematics_table(SPEC, 10.0, 19)
    assert fast["C_vx"] == pytest.approx(10.0 * slow["C_vx"], rel=1e-12, abs=1e-15)
    assert fast["C_ay"] == pytest.approx(100.0 * slow["C_ay"], rel=1e-12, abs=1e-15)


# ----------------------------------------------------------------------------------------------
# Reduced inertia and weight moment


MASSES = dict(
    crank_mass=1.2,
    crank_cg=0.04,
    coupler_mass=3.0,
    coupler_cg=0.16,
    coupler_cg_angle=math.radians(20),
    coupler_inertia=0.025,
    rocker_mass=1.5,
    rocker_cg=0.11,
    rocker_inertia=0.0068,
    tie_mass=2.0,
    side_mass=1.0,
    side_cg=0.08,
    side_inertia=0.0023,
    shuttle_mass=10.0,
)
GRAVITY = (0.3, -9.81)


def test_reduced_inertia_is_the_definition_with_numerical_velocities(numerical):
    """J = sum m |v_S / omega|^2 + J_S (omega_k / omega)^2 with every centre of mass and link angle from the
    fsolve positions (central differences): coupler, two rockers, tie, side link, shuttle."""
    g = GEOMETRY._replace(**MASSES)
    reduced = preset_reduced(g, None)
    O2 = g.frame * cmath.exp(1j * g.frame_angle)
    s = g.beam_length * cmath.exp(1j * g.beam_angle)
    bc_angle = cmath.phase(walking_beam.side(g))
    for phi, entry in numerical.items():
        for points in entry.values():
            th3, th4 = points["th3"], points["th4"]
            points["S2"] = points["A"] + g.coupler_cg * cmath.exp(1j * (th3 + g.coupler_cg_angle))
            points["S3"] = O2 + g.rocker_cg * cmath.exp(1j * th4)
            points["S5"] = points["S3"] + s
            points["S6"] = points["E"] + g.side_cg * cmath.exp(1j * (th3 + bc_angle))
        v = {key: first_difference(entry, key) for key in ("S2", "S3", "S5", "B", "S6", "C")}
        w3 = (entry[1e-4]["th3"] - entry[-1e-4]["th3"]) / 2e-4
        w4 = (entry[1e-4]["th4"] - entry[-1e-4]["th4"]) / 2e-4
        expected = (
            g.coupler_mass * abs(v["S2"]) ** 2
            + g.coupler_inertia * w3**2
            + g.rocker_mass * (abs(v["S3"]) ** 2 + abs(v["S5"]) ** 2)
            + 2.0 * g.rocker_inertia * w4**2
            + g.tie_mass * abs(v["B"]) ** 2
            + g.side_mass * abs(v["S6"]) ** 2
            + g.side_inertia * w3**2
            + g.shuttle_mass * abs(v["C"]) ** 2
        )
        assert reduced(phi)[0] == pytest.approx(expected, rel=1e-7)


def test_inertia_derivative_and_weight_moment_match_differences():
    """dJ/dphi against a central difference of J; M_weight = -dV/dphi with the potential
    V = -g . sum m S (centres of mass from the closed-form points)."""
    g = GEOMETRY._replace(**MASSES)
    reduced = preset_reduced(g, GRAVITY)
    gravity = complex(*GRAVITY)
    O2 = g.frame * cmath.exp(1j * g.frame_angle)
    bc_angle = cmath.phase(walking_beam.side(g))

    def potential(phi):
        (th3, _, _, th4, _, _), points = walking_beam.solve(phi, g)
        centres = [
            (g.crank_mass, g.crank_cg * cmath.exp(1j * phi)),
            (g.coupler_mass, points["A"][0] + g.coupler_cg * cmath.exp(1j * (th3 + g.coupler_cg_angle))),
            (2.0 * g.rocker_mass, O2 + g.rocker_cg * cmath.exp(1j * th4)),
            (g.tie_mass, points["B"][0]),
            (g.side_mass, points["E"][0] + g.side_cg * cmath.exp(1j * (th3 + bc_angle))),
            (g.shuttle_mass, points["C"][0]),
        ]
        return -sum(m * (gravity.conjugate() * S).real for m, S in centres)

    h = 1e-5
    for phi in ANGLES:
        J_plus, J_minus = reduced(phi + h)[0], reduced(phi - h)[0]
        assert reduced(phi)[1] == pytest.approx((J_plus - J_minus) / (2 * h), rel=1e-6, abs=1e-9)
        assert reduced(phi)[2] == pytest.approx(
            -(potential(phi + h) - potential(phi - h)) / (2 * h), rel=1e-6, abs=1e-8
        )
        assert reduced(phi)[3:] == pytest.approx(
            (walking_beam.solve(phi, g)[1]["C"][0].real, walking_beam.solve(phi, g)[1]["C"][1].real), abs=1e-15
        )


def coasting(**mechanism_changes):
    """The bundled walking beam coasting from 10 rad/s: no drive, no loads (conservative), 0.7 s."""
    data = scene(
        SCENE,
        machine__drive=None,
        machine__loads=[],
        scenario__duration=0.7,
        scenario__initial={"phi": 0.3, "omega": 10.0},
        solver={"method": "DOP853", "rtol": 1e-10, "atol": 1e-12},
    )
    data["machine"]["mechanism"].update(mechanism_changes)
    return data


def test_coasting_without_gravity_keeps_J_omega_squared():
    """Conservative and weightless: 1/2 J(phi) omega^2 stays the initial kinetic energy while omega itself
    swings by tens of percent."""
    data = coasting()
    data["machine"]["gravity"] = None
    model = model_of(data)
    trajectory = simulate_complete(model)
    times = np.linspace(0.0, 0.7, 701)
    columns = model.columns(times, trajectory(times))
    energy = columns["J"] * columns["omega"] ** 2
    assert np.ptp(columns["omega"]) / columns["omega"].mean() > 0.1
    assert np.ptp(energy) / energy[0] < 1e-8


def test_coasting_under_gravity_keeps_kinetic_plus_potential_energy():
    model = model_of(coasting())
    trajectory = simulate_complete(model)
    times = np.linspace(0.0, 0.7, 701)
    columns = model.columns(times, trajectory(times))
    phis = columns["phi"]
    # V(phi) = -integral of M_weight dphi, by the trapezoidal rule on a fine grid of phi
    grid = np.linspace(phis.min(), phis.max(), 20001)
    weight = np.array([model.reduced(phi)[2] for phi in grid])
    V = -np.concatenate([[0.0], np.cumsum(0.5 * (weight[1:] + weight[:-1]) * np.diff(grid))])
    total = columns["E_kinetic"] + np.interp(phis, grid, V)
    assert np.ptp(V) > 5.0  # the weight matters (J)
    assert np.ptp(total) / columns["E_kinetic"][0] < 1e-6


def test_shuttle_loads_are_forces_on_the_shuttle_bar_reduced_through_dx_dphi():
    """M = F dx_C/dphi, -c v_x dx_C/dphi and -k (x_C - x0) dx_C/dphi."""
    data = scene(SCENE, scenario__duration=0.1)
    data["machine"]["loads"] = [
        {"type": "shuttle_constant", "force": 25.0},
        {"type": "shuttle_viscous", "coefficient": 150.0},
        {"type": "shuttle_spring", "stiffness": 400.0, "free_position": 0.3},
    ]
    model = model_of(data)
    trajectory = simulate_complete(model)
    times = np.linspace(0.0, 0.1, 51)
    columns = model.columns(times, trajectory(times))
    dx = np.array([walking_beam.solve(phi, GEOMETRY)[1]["C"][1].real for phi in columns["phi"]])
    x = np.array([walking_beam.solve(phi, GEOMETRY)[1]["C"][0].real for phi in columns["phi"]])
    assert columns["x_shuttle"] == pytest.approx(x, abs=1e-15)
    assert columns["v_shuttle"] == pytest.approx(dx * columns["omega"], abs=1e-14)
    assert columns["M_shuttle_constant"] == pytest.approx(25.0 * dx, abs=1e-13)
    assert columns["M_shuttle_viscous"] == pytest.approx(-150.0 * dx * dx * columns["omega"], abs=1e-12)
    assert columns["M_shuttle_spring"] == pytest.approx(-400.0 * (x - 0.3) * dx, abs=1e-12)


# ----------------------------------------------------------------------------------------------
# Drawing


def test_drawing_keeps_every_link_length():
    g = GEOMETRY
    for phi in ANGLES[::6]:
        outline = mechanism_outline(SPEC, phi)
        length = lambda strip: float(np.hypot(*(strip[-1] - strip[0])))  # noqa: E731
        assert length(outline["crank"]) == pytest.approx(g.crank, abs=1e-12)
        for rocker in outline["rocker"]:
            assert length(rocker) == pytest.approx(g.rocker, abs=1e-12)
        for part in ("tie", "shuttle"):
            assert length(outline[part]) == pytest.approx(g.beam_length, abs=1e-12)
        assert length(outline["side"]) == pytest.approx(abs(walking_beam.side(g)), abs=1e-12)
        triangle = outline["coupler"]
        assert length(triangle[:2]) == pytest.approx(g.coupler, abs=1e-12)
        assert length(triangle[[0, 2]]) == pytest.approx(g.coupler_point, abs=1e-12)


# ----------------------------------------------------------------------------------------------
# Command line and bad input


def test_kinematics_command_writes_csv_png_and_json(tmp_path, capsys):
    out, plot = tmp_path / "kin.csv", tmp_path / "kin"
    code, stdout, err = run_cli(
        capsys, "kinematics", "walking_beam", "--points", "73", "--out", str(out), "--plot", str(plot), "--json"
    )
    assert code == 0, err
    summary = json.loads(stdout)
    assert summary["mechanism"] == "walking_beam" and set(summary["joints"]) == {"A", "B", "C", "D", "E"}
    assert summary["joints"]["A"]["v_max"] == pytest.approx(1.0)
    assert summary["joints"]["C"]["v_max"] == pytest.approx(summary["joints"]["D"]["v_max"])
    with out.open(newline="") as handle:
        rows = list(csv.reader(handle))
    table = kinematics_table(SPEC, 10.0, 73)
    assert rows[0] == list(table)
    values = np.array(rows[1:], dtype=float)
    assert values[:, rows[0].index("C_ay")] == pytest.approx(table["C_ay"], rel=1e-11, abs=1e-12)
    assert plot.with_suffix(".png").read_bytes().startswith(b"\x89PNG\r\n\x1a\n")


@pytest.mark.parametrize("scene_name, columns", [("engine", {"B", "C"}), ("four_bar_rocker", {"B", "C"})])
def test_kinematics_command_for_the_other_mechanisms(capsys, scene_name, columns):
    code, stdout, err = run_cli(capsys, "kinematics", scene_name, "--points", "37", "--omega", "5", "--json")
    assert code == 0, err
    joints = json.loads(stdout)["joints"]
    assert set(joints) == columns
    crank = 0.04  # both scenes have a 40 mm crank: its pin moves at a omega, a omega^2
    assert joints["B"]["v_max"] == pytest.approx(crank * 5.0) and joints["B"]["a_max"] == pytest.approx(crank * 25.0)


@pytest.mark.parametrize(
    "argv, expected",
    [
        (["--omega", "0"], ["--omega 0", "> 0 rad/s"]),
        (["--omega", "nan"], ["--omega nan", "> 0 rad/s"]),
        (["--points", "2"], ["--points 2", "3 to 100000"]),
        (["--set", "machine.mechanism.crank=0.25"], ["cannot be assembled for crank angles", "Grashof"]),
        (
            ["--set", "machine.mechanism.beam_angle_deg=0"],
            ["machine.mechanism", "parallelogram B-C-D-E flattens", "coupler side BC", "beam direction 0 deg"],
        ),
        (["--set", "machine.mechanism.beam_angle_deg=-100"], ["parallelogram O2-B-E-O3 flattens", "rocker O2B"]),
        (["--set", "machine.mechanism.coupler_point=-0.3"], ["coupler_point", "greater than 0"]),
    ],
)
def test_kinematics_bad_input_is_a_clear_message(capsys, argv, expected):
    code, stdout, err = run_cli(capsys, "kinematics", "walking_beam", *argv)
    assert code == 2
    for text in expected:
        assert text in err, (text, err)


def test_kinematics_of_a_scene_without_mechanism_and_shuttle_load_without_walking_beam(tmp_path, capsys):
    code, _, err = run_cli(capsys, "kinematics", "startup")
    assert code == 2 and "has no mechanism" in err and "machine.mechanism" in err
    data = read_scene_data(SCENES / "four_bar_rocker.yaml")
    data["machine"]["loads"] = [{"type": "shuttle_viscous", "coefficient": 1.0}]
    path = write_scene(tmp_path, json.dumps(data))
    code, _, err = run_cli(capsys, "describe", str(path))
    assert code == 2 and "shuttle_viscous" in err and "walking_beam" in err and "four_bar" in err


def test_recording_animates_the_eight_links(tmp_path):
    """The Rerun recording draws every link; each frame's shuttle bar is the beam vector s (y flipped:
    Rerun's views have y down) and the rockers come as a bundle of two strips."""
    import pyarrow as pa
    from rerun.chunk import RrdReader

    from mech_regulator.viz.recording import record_run

    model = model_of(scene(SCENE, scenario__duration=0.1))
    trajectory = simulate_complete(model)
    times = trajectory.samples(1000.0)
    path = tmp_path / "walking_beam.rrd"
    record_run(model, times, trajectory(times), path)
    store = RrdReader(path).store()
    entities = set(store.schema().entity_paths())
    assert {
        f"/mechanism/{part}" for part in ("crank", "coupler", "rocker", "tie", "side", "shuttle", "frame", "joints")
    } <= entities
    frames = {}
    for part in ("shuttle", "rocker"):
        frames[part] = [
            strips
            for chunk in store.stream()
            if chunk.entity_path == f"/mechanism/{part}" and not chunk.is_static
            for strips in chunk.to_record_batch()
            .column("LineStrips2D:strips")
            .cast(pa.list_(pa.list_(pa.list_(pa.float64()))))
            .to_pylist()
        ]
    assert len(frames["shuttle"]) > 5
    s = GEOMETRY.beam_length * cmath.exp(1j * GEOMETRY.beam_angle)
    for (strip,) in frames["shuttle"]:
        (x0, y0), (x1, y1) = strip
        assert complex(x1 - x0, -(y1 - y0)) == pytest.approx(s, abs=1e-6)
    assert all(len(strips) == 2 for strips in frames["rocker"])
