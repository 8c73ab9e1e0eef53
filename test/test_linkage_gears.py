"""Gear pairs in a linkage (mechanisms/linkage/gears.py, docs/theory.md §5.4) against closed forms written here.

A gear pair on frame pivots turns its second gear at -z1/z2 (external) or +z1/z2 (internal) times the first's rate;
an epicyclic train with its arm as the crank, its sun fixed, turns the planet at 1 + z_s/z_p and the ring at
1 + z_s/z_r (Willis: (omega_p - omega_arm) / (omega_sun - omega_arm) = -z_s/z_p); a geared crank's J is
J1 + J2 (z1/z2)^2. The generated code (both paths) gives the general solver's numbers; the kinetostatics' balancing
moment equals the reduced one (its tooth force is then the one that balances the gear), and the tooth force of a
gear pair under a torque is that torque over the pitch radius. A whole scene file with a gear pair goes through
the scene's validation; what is refused is named.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from support import run_cli

from mech_regulator.mechanisms.linkage import (
    Joint,
    Link,
    Linkage,
    LinkageError,
    checked,
    flat_kinetostatics,
    flat_program,
    make_reduced,
    solve,
    symbolic,
)
from mech_regulator.mechanisms.linkage.gears import GearMesh
from mech_regulator.mechanisms.linkage.kinetostatics import make_kinetostatics
from mech_regulator.scene import SceneError, load_scene, validate_scene

ANGLES = np.linspace(0.0, 2.0 * math.pi, 13)[:-1] + 0.137
GRAVITY = (0.3, -9.81)


def gear_pair(z1: int, z2: int, internal: bool = False, distance: float = 0.3) -> Linkage:
    """A crank gear of z1 teeth about A driving a gear of z2 teeth about B on the frame, `distance` apart; each gear
    with an off-axis centre of mass (so that its J term is m c^2 + I times its rate squared)."""
    links = (
        Link("frame", {"A": 0j, "B": complex(distance, 0.0)}),
        Link("crank", {"A": 0j}, mass=2.0, centre=0.01j, inertia=0.5),
        Link("gear", {"B": 0j}, mass=1.0, centre=0.02 + 0j, inertia=0.2),
    )
    joints = (
        Joint("A", "revolute", ("frame", "crank")),
        Joint("B", "revolute", ("frame", "gear")),
        Joint("M", "gear", ("crank", "gear"), gear=GearMesh(("A", "B"), teeth=(z1, z2), internal=internal)),
    )
    return Linkage(links, joints, "frame", "crank", output_link="gear")


def epicyclic(z_sun: int, z_planet: int, z_ring: int) -> Linkage:
    """An arm (the crank) about A carrying a planet at P that meshes with the fixed sun (the frame's gear about A)
    and with a ring about A (internal)."""
    arm = 0.2 * (z_sun + z_planet) / (z_sun + 2 * z_planet)
    links = (
        Link("frame", {"A": 0j, "R": 0j}),
        Link("arm", {"A": 0j, "P": complex(arm, 0.0)}, mass=1.0, centre=complex(arm / 2, 0.0), inertia=0.01),
        Link("planet", {"P": 0j}, mass=0.5, inertia=0.001),
        Link("ring", {"R": 0j}, mass=2.0, inertia=0.05),
    )
    joints = (
        Joint("A", "revolute", ("frame", "arm")),
        Joint("P", "revolute", ("arm", "planet")),
        Joint("S", "gear", ("frame", "planet"), gear=GearMesh(("A", "P"), teeth=(z_sun, z_planet), carrier="arm")),
        Joint("R", "revolute", ("frame", "ring")),
        Joint(
            "Q",
            "gear",
            ("planet", "ring"),
            gear=GearMesh(("P", "R"), teeth=(z_planet, z_ring), internal=True, carrier="arm"),
        ),
    )
    return Linkage(links, joints, "frame", "arm", output_link="ring")


def geared_press() -> Linkage:
    """A crank gear (60 teeth) driving a pinion (30) that is the crank of a slider-crank: the pinion turns twice
    per crank turn, its crank pin C 0.05 m off its axis."""
    links = (
        Link("frame", {"A": 0j, "B": 0.3 + 0j, "G": 0.3 + 0j}),
        Link("crank", {"A": 0j}, mass=2.0, inertia=0.5),
        Link("pinion", {"B": 0j, "C": 0.05 + 0j}, mass=1.0, inertia=0.02),
        Link("rod", {"C": 0j, "D": 0.25 + 0j}, mass=1.5, centre=0.125 + 0j, inertia=0.01),
        Link("ram", {"D": 0j, "G": 0j}, mass=3.0),
    )
    joints = (
        Joint("A", "revolute", ("frame", "crank")),
        Joint("B", "revolute", ("frame", "pinion")),
        Joint("M", "gear", ("crank", "pinion"), gear=GearMesh(("A", "B"), teeth=(60, 30))),
        Joint("C", "revolute", ("pinion", "rod")),
        Joint("D", "revolute", ("rod", "ram")),
        Joint("G", "prismatic", ("frame", "ram")),
    )
    return Linkage(links, joints, "frame", "crank", output_joint="G")


@pytest.mark.parametrize(
    "z1, z2, internal, ratio",
    [(40, 20, False, -2.0), (20, 50, False, -0.4), (20, 60, True, 1.0 / 3.0), (60, 24, True, 2.5)],
)
def test_gear_pair_ratio_and_geared_crank_inertia(z1, z2, internal, ratio):
    """theta_2 = -z1/z2 phi (external), +z1/z2 phi (internal), with theta_2' and theta_2'' = 0; the structure counts
    the mesh as p4 (n = 2, p5 = 2, p4 = 1, W = 1); J = J1 + J2 (z1/z2)^2 with J_k = m_k c_k^2 + I_k, dJ/dphi = 0."""
    linkage = gear_pair(z1, z2, internal, distance=0.3 if not internal else 0.1)
    structure = checked(linkage)
    assert (structure.moving_links, structure.lower_pairs, structure.higher_pairs, structure.freedom) == (2, 2, 1, 1)
    for phi in ANGLES:
        poses = solve(linkage, structure, phi)
        assert (poses["gear"][1], poses["gear"][3], poses["gear"][5]) == pytest.approx(
            (ratio * phi, ratio, 0.0), abs=1e-12
        )
    J1, J2 = 2.0 * 0.01**2 + 0.5, 1.0 * 0.02**2 + 0.2
    for reduced in (make_reduced(linkage, structure, GRAVITY), symbolic.make_reduced(linkage, structure, GRAVITY)):
        for phi in ANGLES:
            J, dJ, _, angle, rate = reduced(phi)
            assert (J, dJ, rate) == pytest.approx((J1 + J2 * (z1 / z2) ** 2, 0.0, ratio), abs=1e-12)
            assert math.cos(angle) == pytest.approx(math.cos(ratio * phi), abs=1e-12)


def test_epicyclic_train_ratios_by_willis():
    """Arm the crank, sun fixed: (omega_p - omega_arm) / (0 - omega_arm) = -z_s/z_p, so omega_p = 1 + z_s/z_p; the
    ring through the planet (internal, +z_p/z_r on the arm): omega_r = 1 + z_s/z_r; J of the train the sum of each
    body's inertia times its rate squared plus the planet's mass times the arm's length squared."""
    z_sun, z_planet, z_ring = 60, 30, 120
    linkage = epicyclic(z_sun, z_planet, z_ring)
    structure = checked(linkage)
    assert (structure.moving_links, structure.lower_pairs, structure.higher_pairs, structure.freedom) == (3, 3, 2, 1)
    planet_rate, ring_rate = 1 + z_sun / z_planet, 1 + z_sun / z_ring
    arm = abs(linkage.link("arm").points["P"])
    for phi in ANGLES:
        poses = solve(linkage, structure, phi)
        assert (poses["planet"][1], poses["planet"][3]) == pytest.approx((planet_rate * phi, planet_rate), abs=1e-12)
        assert (poses["ring"][1], poses["ring"][3]) == pytest.approx((ring_rate * phi, ring_rate), abs=1e-12)
    J = (0.01 + 1.0 * (arm / 2) ** 2) + 0.5 * arm**2 + 0.001 * planet_rate**2 + 0.05 * ring_rate**2
    for reduced in (make_reduced(linkage, structure, GRAVITY), symbolic.make_reduced(linkage, structure, GRAVITY)):
        for phi in ANGLES:
            assert reduced(phi)[:2] == pytest.approx((J, 0.0), abs=1e-12)


def test_geared_press_generated_code_equals_the_general_solver_and_balances():
    """A slider-crank hung on a pinion: the generated reduction equals the general solver's (1e-12 of each size);
    the pinion turns -2 phi; the balancing moment from the reactions (through the tooth force) equals the reduced
    moment J epsilon + J'/2 omega^2 - M_weight - Q q'."""
    linkage = geared_press()
    structure = checked(linkage)
    assert [group.kind for group in structure.groups] == ["gear", "RRP"]
    general, generated = make_reduced(linkage, structure, GRAVITY), symbolic.make_reduced(linkage, structure, GRAVITY)
    table = np.array([general(phi) for phi in ANGLES])
    assert np.array([generated(phi) for phi in ANGLES]) == pytest.approx(table, abs=1e-12 * np.abs(table).max())
    loads = make_kinetostatics(linkage, structure, GRAVITY)
    for phi, (J, dJ, weight, _, dq) in zip(ANGLES, table):
        omega, epsilon, force = 7.0, -3.0, 150.0
        assert loads(phi, omega, epsilon, force).balancing == pytest.approx(
            J * epsilon + 0.5 * dJ * omega**2 - weight - force * dq, abs=1e-10 * (1 + abs(J * epsilon))
        )


def test_tooth_force_is_the_driven_torque_over_the_pitch_radius():
    """A torque Q on the driven gear (its output) at rest: the tooth force is Q / r_2 (r_2 = 0.1 m for 40:20 teeth
    0.3 m apart) and the balancing moment -Q q' with q' = theta_2' = -2, i.e. 2 Q."""
    linkage = gear_pair(40, 20)
    loads = make_kinetostatics(linkage, checked(linkage), None)
    torque = 12.0
    result = loads(0.4, 0.0, 0.0, torque)
    assert abs(result.reactions["M"]) == pytest.approx(torque / 0.1, rel=1e-12)
    assert result.balancing == pytest.approx(2.0 * torque, rel=1e-12)


def test_refusals_name_the_mesh():
    """Radii that do not fit the centres' distance and a slider-crank hung on a gear turning 1.5 times per crank
    turn are refused with what was found."""
    wrong = gear_pair(40, 20)
    mesh = wrong.joint("M")
    radii = Joint("M", "gear", mesh.links, gear=GearMesh(("A", "B"), radii=(0.2, 0.2)))
    with pytest.raises(LinkageError, match=r"pitch radii 0.2 and 0.2 m \(external\) need the centres 0.4 m apart"):
        checked(Linkage(wrong.links, wrong.joints[:2] + (radii,), "frame", "crank"))
    press = geared_press()
    fractional = Joint("M", "gear", ("crank", "pinion"), gear=GearMesh(("A", "B"), teeth=(60, 40)))
    joints = tuple(fractional if joint.name == "M" else joint for joint in press.joints)
    with pytest.raises(LinkageError, match="the gear pinion turns -1.5 times per crank turn and carries C"):
        checked(Linkage(press.links, joints, "frame", "crank", output_joint="G"))


def test_generated_joint_loads_equal_the_general_solvers():
    """flat_kinetostatics.joint_loads written out per linkage (symbolic.joint_loads_source, what `kinematics` and both
    paths run) gives the general solver's reactions, tooth force included, rates and balancing moment (1e-10 of each
    size)."""
    linkage = geared_press()
    program = flat_program.encode(linkage, checked(linkage).groups, GRAVITY)
    generated = symbolic.reference_function(symbolic.joint_loads_source(program)[0])
    for phi in ANGLES:
        expected = flat_kinetostatics.joint_loads(phi, 7.0, 150.0, program, 0)
        found = generated(phi, 7.0, 150.0, program, 0)
        for wanted, got in zip(expected, found):
            wanted, got = np.atleast_1d(wanted), np.atleast_1d(np.array(got))
            assert got == pytest.approx(wanted, abs=1e-10 * (1.0 + np.abs(wanted).max()))


def test_the_geared_scene_through_structure_and_simulate(tmp_path, capsys):
    """The bundled geared_shaker: `structure` prints the mesh as p4 and the gear group (text and JSON) and draws the
    pitch circles; `simulate` on the reference path runs it with its recording; radii that do not fit its centres
    are refused at once (exit 2) with the mesh named."""
    plot = tmp_path / "structure.png"
    code, out, _ = run_cli(capsys, "structure", "geared_shaker", "--plot", str(plot))
    assert code == 0 and "W = 3*4 - (2*5 + 1 - 0 - 0) - 0 = 1" in out
    assert "group 1: gear pinion about B, mesh M with bull_gear on frame: ratio -2, pitch radii 0.2 and 0.1 m" in out
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    code, out, _ = run_cli(capsys, "structure", "geared_shaker", "--json")
    summary = json.loads(out)
    assert (summary["p4"], [group["class"] for group in summary["groups"]]) == (1, ["gear", "II"])
    record = tmp_path / "run.rrd"
    code, out, _ = run_cli(
        capsys,
        "simulate",
        "geared_shaker",
        "--set",
        "solver.path=reference",
        "--set",
        "scenario.duration=0.3",
        "--record",
        str(record),
    )
    assert code == 0 and "complete at t = 0.3 s" in out and record.stat().st_size > 0
    code, _, err = run_cli(
        capsys,
        "structure",
        "geared_shaker",
        "--set",
        "machine.mechanism.joints.M.teeth=null",
        "--set",
        "machine.mechanism.joints.M.radii=[0.2,0.2]",
    )
    assert code == 2 and "the gear mesh M: pitch radii 0.2 and 0.2 m (external) need the centres 0.4 m apart" in err


def test_a_gear_scene_survives_its_own_dump_and_gear_keys_on_a_lower_pair_are_refused():
    """Commands that re-validate a scene (flywheel, sweep) read its full dump, defaults included: accepted; a gear
    key on a revolute joint is named."""
    data = load_scene("geared_shaker").model_dump()
    assert validate_scene(data).machine.mechanism.joints["M"].teeth == [60, 30]
    data["machine"]["mechanism"]["joints"]["B"]["teeth"] = [10, 20]
    with pytest.raises(SceneError, match=r"\['teeth'\] belong to a gear; this joint is revolute"):
        validate_scene(data)
