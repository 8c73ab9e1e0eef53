"""Cam pairs (mechanisms/cam_laws.py, mechanisms/linkage/cam.py; docs/theory.md §5.7, docs/linkages.md "Cams"): the
follower laws against their closed forms written here, the eccentric (circular-arc) cam's pressure angle and radius
of curvature, a translating follower's J = m s'^2, the harmonic follower's jump speed, source 001's rocking roller
follower (W = 1 with its passive freedom) as a scene through `structure`, the generated reduction, the jump ending
a run, a cam run's energy balance, and what is refused."""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest
from support import run_cli

from mech_regulator.analysis import RunDigest, energy, stream
from mech_regulator.analysis.energy import energy_balance
from mech_regulator.mechanisms.cam_laws import Segment, SegmentLaw, TableLaw
from mech_regulator.mechanisms.linkage import Joint, Link, Linkage, LinkageError, analyse
from mech_regulator.mechanisms.linkage.cam import CamPair, CamSpec
from mech_regulator.mechanisms.presets import linkage_core
from mech_regulator.model import build_model
from mech_regulator.scene import SceneError, load_scene, validate_scene
from mech_regulator.solvers import cam_contact, simulate
from mech_regulator.solvers.cam_contact import _pairs, check_contact
from mech_regulator.solvers.compiled import run as compiled_run
from mech_regulator.solvers.cosim import cosimulate
from mech_regulator.solvers.time_domain import _segment
from mech_regulator.solvers.trajectory import Trajectory

BETA = math.radians(120.0)  # a rise's or return's angle [rad]
LIFT = 0.008  # its lift [m]
X = np.linspace(0.0, 1.0, 41)[1:-1]  # inside the segment (a law's s'' jumps at its ends)


def closed_form(law: str, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """s, s', s'' of a rise of LIFT over BETA by `law`, written from the textbook formulas."""
    h, b = LIFT, BETA
    if law == "uniform":
        return h * theta / b, np.full_like(theta, h / b), np.zeros_like(theta)
    if law == "harmonic":
        return (
            h / 2 * (1 - np.cos(np.pi * theta / b)),
            h * np.pi / (2 * b) * np.sin(np.pi * theta / b),
            h * np.pi**2 / (2 * b**2) * np.cos(np.pi * theta / b),
        )
    if law == "cycloidal":
        return (
            h * (theta / b - np.sin(2 * np.pi * theta / b) / (2 * np.pi)),
            h / b * (1 - np.cos(2 * np.pi * theta / b)),
            2 * np.pi * h / b**2 * np.sin(2 * np.pi * theta / b),
        )
    x = theta / b
    return (
        h * (10 * x**3 - 15 * x**4 + 6 * x**5),
        h / b * (30 * x**2 - 60 * x**3 + 30 * x**4),
        h / b**2 * (60 * x - 180 * x**2 + 120 * x**3),
    )


def rise_dwell_return(law: str) -> SegmentLaw:
    """Rise by `law` over BETA, dwell 20 deg, return by `law` over BETA, dwell the rest."""
    return SegmentLaw(
        (
            Segment("rise", BETA, law, LIFT),
            Segment("dwell", math.radians(20.0)),
            Segment("return", BETA, law, LIFT),
            Segment("dwell", math.radians(100.0)),
        )
    )


@pytest.mark.parametrize("law", ["uniform", "harmonic", "cycloidal", "polynomial_345"])
def test_follower_laws_give_their_closed_forms_on_the_rise_dwell_and_return(law):
    motion = rise_dwell_return(law)
    theta = X * BETA
    for got, expected in zip(motion.evaluate(theta), closed_form(law, theta)):
        assert got == pytest.approx(expected, rel=1e-12, abs=1e-15)
    dwell = motion.evaluate(BETA + np.radians([1.0, 10.0, 19.0]))
    assert [list(part) for part in dwell] == [[LIFT] * 3, [0.0] * 3, [0.0] * 3]
    back = BETA + math.radians(20.0) + theta  # the return mirrors the rise: s = h - s_rise, s' and s'' negated
    s, ds, dds = closed_form(law, theta)
    for got, expected in zip(motion.evaluate(back), (LIFT - s, -ds, -dds)):
        assert got == pytest.approx(expected, rel=1e-12, abs=1e-15)
    assert motion.evaluate(np.array([2 * math.pi + 0.5 * BETA]))[0][0] == pytest.approx(
        motion.evaluate(np.array([0.5 * BETA]))[0][0], abs=1e-15
    )  # periodic over the turn


def test_a_table_law_follows_the_smooth_law_it_was_sampled_from():
    theta = np.linspace(0.0, 2 * math.pi, 720, endpoint=False)
    cycloidal = rise_dwell_return("cycloidal")
    table = TableLaw(list(theta), list(cycloidal.evaluate(theta)[0]))
    check = np.linspace(0.01, 2 * math.pi - 0.01, 500)
    for got, expected, scale in zip(table.evaluate(check), cycloidal.evaluate(check), (1e-7, 1e-5, 1e-2)):
        assert np.max(np.abs(got - expected)) < scale * np.max(np.abs(expected))


@pytest.mark.parametrize(
    "segments, expected",
    [
        ((Segment("rise", math.pi, "harmonic", 0.01), Segment("return", math.pi / 2, "harmonic", 0.01)), "span 270"),
        ((Segment("rise", math.pi, "harmonic", 0.01), Segment("return", math.pi, "harmonic", 0.02)), "rises 0.01"),
    ],
)
def test_laws_that_do_not_close_the_turn_are_refused(segments, expected):
    with pytest.raises(ValueError, match=expected):
        SegmentLaw(segments)


class EccentricCam:
    """The follower law of a circular disc of radius Rc whose centre is eps from the pivot (at -90 deg at theta =
    0), under a centred translating follower moving along +y with a roller of radius r: the roller's centre is at
    y = eps sin(a) + sqrt(R^2 - eps^2 cos(a)^2), a = theta - pi/2, R = Rc + r; s = y - (R - eps)."""

    def __init__(self, disc: float, eccentricity: float, roller: float):
        import sympy

        theta = sympy.Symbol("theta")
        R, eps = disc + roller, eccentricity
        a = theta - sympy.pi / 2
        y = eps * sympy.sin(a) + sympy.sqrt(R**2 - eps**2 * sympy.cos(a) ** 2) - (R - eps)
        self.functions = [sympy.lambdify(theta, expr, "numpy") for expr in (y, y.diff(theta), y.diff(theta, 2))]

    def evaluate(self, theta):
        return tuple(np.asarray(f(np.asarray(theta, dtype=float)), dtype=float) for f in self.functions)

    def kinks(self):
        return np.zeros(0)


def translating_pair(
    law,
    contact: str = "roller",
    roller: float | None = 0.01,
    base: float = 0.03,
    stiffness: float = 0.0,
    preload: float = 0.0,
    masses=(0.4, 0.1),
    gravity=None,
) -> CamPair:
    """A cam pair on the crank 'cam' about (0, 0): a centred follower on a guide along +y, with a roller."""
    rolling = contact == "roller"
    links = (
        Link("frame", {"A": 0j, "G": 0j}),
        Link("cam", {"A": 0j}, mass=1.0, inertia=1e-3),
        Link("follower", {"G": 0j, "R": 0j, "K": 0j}, mass=masses[0], centre=0.05j),
    )
    joints = [
        Joint("A", "revolute", ("frame", "cam")),
        Joint("G", "prismatic", ("frame", "follower"), direction=math.pi / 2),
    ]
    if rolling:
        links += (Link("roller", {"R": 0j}, mass=masses[1], roller_radius=roller),)
        joints += [Joint("R", "revolute", ("follower", "roller"))]
    spec = CamSpec(law, contact, base, 0.0, stiffness, preload)
    joints.append(Joint("K", "cam", ("cam", "roller" if rolling else "follower"), cam=spec))
    linkage = Linkage(links, tuple(joints), "frame", "cam")
    structure = analyse(linkage)
    assert structure.freedom == 1 and structure.refusal() is None
    return CamPair(linkage, structure.groups[0], gravity)


def test_an_eccentric_cam_has_its_closed_form_pressure_angle_and_radius_of_curvature():
    """The contact normal passes through the disc's centre: sin(alpha) = eps |cos a| / (Rc + r); the profile is the
    disc, its radius of curvature Rc everywhere."""
    disc, eps, roller = 0.04, 0.012, 0.01
    pair = translating_pair(EccentricCam(disc, eps, roller), roller=roller, base=disc - eps)
    phi = np.linspace(0.0, 2 * math.pi, 181)
    expected = np.arcsin(eps * np.abs(np.cos(phi - math.pi / 2)) / (disc + roller))
    assert pair.pressure_angle(phi) == pytest.approx(expected, abs=1e-12)
    assert pair.profile_radius(phi) == pytest.approx(np.full_like(phi, disc), rel=1e-10)
    profile = pair.profile(360)  # the disc in the cam's coordinates: its centre at -i eps
    assert np.abs(profile + 1j * eps) == pytest.approx(np.full(360, disc), rel=1e-12)


def test_a_translating_followers_J_is_its_mass_times_s_prime_squared():
    """J_f = (m_follower + m_roller) s'^2 (the machine's J = J0 + that), dJ_f = its phi-derivative, checked against
    the follower's poses (r' of the follower, P' of the roller) and a central difference."""
    pair = translating_pair(rise_dwell_return("polynomial_345"), masses=(0.4, 0.1))
    phi = np.linspace(0.05, 2 * math.pi - 0.05, 37)
    _, ds, _ = closed_form("polynomial_345", np.clip(phi, 0.0, BETA))
    J, dJ, weight, spring = pair.reduced(phi)
    rising = phi < BETA
    assert J[rising] == pytest.approx(0.5 * ds[rising] ** 2, rel=1e-12)
    for k in range(len(phi)):
        poses = pair.poses(phi[k])
        assert J[k] == pytest.approx(
            0.4 * abs(poses["follower"][2]) ** 2 + 0.1 * abs(poses["roller"][2]) ** 2, rel=1e-12, abs=1e-18
        )
    step = 1e-6
    central = (pair.reduced(phi + step)[0] - pair.reduced(phi - step)[0]) / (2 * step)
    assert dJ == pytest.approx(central, rel=1e-6, abs=1e-12)
    assert list(weight) == [0.0] * len(phi) and list(spring) == [0.0] * len(phi)  # no gravity, no spring


def test_the_jump_speed_of_a_harmonic_follower_with_a_preloaded_spring_is_its_closed_form():
    """Contact is lost first where the harmonic return starts (s = h, s'' = -h/2 (pi/beta)^2): at
    omega_jump = (beta/pi) sqrt(2 (k h + F0) / (m h)); below it the contact force stays positive, above it turns
    negative."""
    k, F0, m = 20000.0, 150.0, 0.5
    pair = translating_pair(rise_dwell_return("harmonic"), stiffness=k, preload=F0, masses=(0.4, 0.1))
    expected = BETA / math.pi * math.sqrt(2 * (k * LIFT + F0) / (m * LIFT))
    speed, where = pair.jump()
    assert speed == pytest.approx(expected, rel=1e-12)
    assert math.degrees(where) % 360 == pytest.approx(120.0, abs=1e-6) or math.degrees(where) % 360 == pytest.approx(
        140.0, abs=1e-6
    )
    phi = np.linspace(0.0, 2 * math.pi, 3601)
    assert np.min(pair.contact_force(phi, 0.99 * expected)[0]) > 0.0
    assert np.min(pair.contact_force(phi, 1.01 * expected)[0]) < 0.0
    needed, normal = pair.contact_force(np.array([math.radians(130.0)]), 0.0)  # at rest on the top dwell
    assert (needed[0], normal[0]) == pytest.approx((F0 + k * LIFT, F0 + k * LIFT), rel=1e-12)


def test_a_roller_larger_than_the_pitch_curves_curvature_is_refused_with_the_angle():
    law = SegmentLaw(
        (
            Segment("rise", math.radians(40.0), "cycloidal", 0.03),
            Segment("return", math.radians(320.0), "cycloidal", 0.03),
        )
    )
    with pytest.raises(
        LinkageError,
        match=r"cam pair K at crank angle [\d.]+ deg: the roller's radius 0.02 m exceeds "
        "the pitch curve's radius of curvature .* undercut",
    ):
        translating_pair(law, roller=0.02, base=0.02)


SOURCE_001_CAM = """
name: rocking_roller_follower
description: source 001's rocking roller-follower cam (fig. 1.27) as a scene
machine:
  inertia: 0.01
  mechanism:
    type: linkage
    frame: {O1: [0.0, 0.0], O2: [0.12, 0.0]}
    crank: cam
    links:
      cam: {points: {O1: [0.0, 0.0]}}
      roller: {points: {R: [0.0, 0.0]}, mass: 0.05}
      follower: {points: {O2: [0.0, 0.0], R: [0.1, 0.0]}, mass: 0.3, centre: [0.05, 0.0], inertia: 2.5e-4}
    joints:
      O1: {type: revolute, links: [frame, cam]}
      K:
        type: cam
        links: [cam, roller]
        contact: roller
        roller_radius: 0.01
        base_radius: 0.04
        law:
          - {motion: rise, law: cycloidal, angle_deg: 150.0, lift: 0.3}
          - {motion: return, law: cycloidal, angle_deg: 150.0, lift: 0.3}
          - {motion: dwell, angle_deg: 60.0}
        spring: {stiffness: 5.0, preload: 1.0}
      R: {type: revolute, links: [roller, follower]}
      O2: {type: revolute, links: [frame, follower]}
  drive: {type: constant, torque: 1.0}
scenario:
  initial: {phi: 0.0, omega: 10.0}
  duration: 0.1
"""


def test_source_001s_rocking_roller_follower_has_W_1_with_its_passive_freedom(tmp_path, capsys):
    """Cam 1, roller 2, rocking follower 3: n = 3, p5 = 3, p4 = 1, one passive freedom (the roller), W = 1; the
    follower and its roller are one group; `structure --plot` draws the profile."""
    scene = tmp_path / "rocking.yaml"
    scene.write_text(SOURCE_001_CAM, encoding="utf-8")
    code, out, _ = run_cli(capsys, "structure", str(scene), "--json")
    assert code == 0
    summary = json.loads(out)
    assert (summary["n"], summary["p5"], summary["p4"], summary["W"]) == (3, 3, 1, 1)
    assert summary["passive"] == ["the roller roller spins about R without moving anything else"]
    assert [(g["type"], g["links"]) for g in summary["groups"]] == [("cam follower", ["follower", "roller"])]
    (cam,) = summary["cams"]
    assert (cam["motion"], cam["contact"], cam["lift"]) == ("oscillating", "roller", pytest.approx(0.3))
    assert 0.0 < cam["pressure_angle_max_deg"] < 90.0 and cam["least_radius"] > 0.0 and cam["jump_speed"] > 0.0
    plot = tmp_path / "rocking.png"
    code, out, _ = run_cli(capsys, "structure", str(scene), "--plot", str(plot))
    assert code == 0 and "W = 3*3 - (2*3 + 1 - 0 - 0) - 1 = 1" in out and "cam pair K: cam cam, roller follower" in out
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_valve_gear_runs_below_its_jump_speed_and_stops_where_contact_is_lost_above_it(capsys):
    """Below the jump speed the run completes; above it the run ends `failed` where the contact force turns
    negative, with an event naming the cam pair, and the contact force is zero there (both paths share the check,
    solvers/cam_contact.py)."""
    code, out, _ = run_cli(capsys, "structure", "valve_gear")
    assert code == 0
    assert "the follower jumps above 587.822 rad/s" in out  # 586.9 without the weight of 0.1 kg along -y
    below = build_model(load_scene("valve_gear", ["solver.path=reference", "scenario.duration=0.02"]))
    assert simulate(below).status == "complete"
    above = build_model(
        load_scene("valve_gear", ["solver.path=reference", "scenario.duration=0.02", "scenario.initial.omega=700"])
    )
    trajectory = simulate(above)
    assert trajectory.status == "failed" and "left its cam (cam pair K)" in trajectory.message
    ((t_lost, what),) = trajectory.events
    assert what == "contact lost at cam pair K" and t_lost == trajectory.t_end < 0.02
    phi, omega = trajectory(t_lost)[:2]
    pair = _pairs(above.scene)[0]
    epsilon = (trajectory(t_lost)[1] - trajectory(t_lost - 1e-7)[1]) / 1e-7
    needed = pair.contact_force(phi, omega, epsilon)[0][0]
    assert abs(needed) < 1e-3 * (pair.spec.preload + pair.spec.stiffness * LIFT)
    assert omega > pair.jump()[0]


@pytest.mark.parametrize("gravity", [9.81, 0.0])
def test_a_cam_run_keeps_its_energy_balance_and_the_spring_stores_what_it_takes(gravity):
    """Over a valve-gear run the works equal the change of kinetic energy (relative 1e-8), and the work of the
    position moments (weight and spring, the reduction's M_weight; the spring's also without gravity) is minus the
    change of the spring's and the weight's energy, F0 s + k s^2 / 2 + m g s, between the run's ends."""
    model = build_model(
        load_scene(
            "valve_gear",
            ["solver.path=reference", "scenario.duration=0.0368"] + ([] if gravity else ["machine.gravity=null"]),
        )
    )
    trajectory = simulate(model)
    assert trajectory.status == "complete"
    balance = energy_balance(model, trajectory)
    assert abs(balance.relative_residual) < 1e-8
    pair = _pairs(model.scene)[0]
    s = pair.motion(trajectory(np.array([0.0, trajectory.t_end]))[0]).s
    stored = pair.spec.preload * s + 0.5 * pair.spec.stiffness * s**2 + 0.1 * gravity * s
    assert s[1] > 0.5 * LIFT  # the run ends with the valve open: the spring holds energy
    assert balance.works["weight"] == pytest.approx(-(stored[1] - stored[0]), rel=1e-7)


def test_the_machines_J_is_the_cams_plus_the_followers_m_s_prime_squared_on_both_solvers():
    """The valve gear's reduced inertia from its generated code (what both paths run) is J0 + m s'^2 with the
    harmonic law's s' (m = tappet and roller, 0.1 kg; J0 the cam's 5e-5 kg m^2) and dJ/dphi = 2 m s' s''; the
    general solver (flat.py) gives the same to 1e-12."""
    from mech_regulator.mechanisms import build_reduced, mechanism_geometry
    from mech_regulator.mechanisms.linkage import make_reduced

    mechanism = load_scene("valve_gear").machine.mechanism
    generated = build_reduced(mechanism, None)
    general = make_reduced(*mechanism_geometry(mechanism), None)
    phi = X * BETA
    _, ds, dds = closed_form("harmonic", phi)
    for k, angle in enumerate(phi):
        J, dJ, weight, q, dq = generated(angle)
        assert (J, dJ) == pytest.approx((5e-5 + 0.1 * ds[k] ** 2, 2 * 0.1 * ds[k] * dds[k]), rel=1e-12)
        assert general(angle) == pytest.approx((J, dJ, weight, q, dq), rel=1e-12, abs=1e-15)


def cam_scene(change) -> dict:
    data = copy.deepcopy(load_scene("valve_gear").model_dump(exclude_none=True))
    change(data["machine"]["mechanism"])
    return data


@pytest.mark.parametrize(
    "change, expected",
    [
        (lambda m: m["joints"]["K"]["law"][1].update(lift=0.001), "a dwell segment takes no law and no lift"),
        (lambda m: m["joints"]["K"]["law"][0].pop("law"), "a rise segment needs a law"),
        (lambda m: m["joints"]["K"]["law"][3].update(angle_deg=90.0), "segments span 350 deg; expected 360 deg"),
        (lambda m: m["joints"]["K"].pop("roller_radius"), "roller_radius is given exactly when contact is roller"),
        (
            lambda m: m["joints"]["K"].update(
                law=[
                    {"motion": "rise", "law": "cycloidal", "angle_deg": 40.0, "lift": 0.03},
                    {"motion": "return", "law": "cycloidal", "angle_deg": 320.0, "lift": 0.03},
                ],
                roller_radius=0.012,
            ),
            "would be undercut",
        ),
        (lambda m: m["frame"].update(guide=[0.05, 0.0]), "the follower's line passes 0.05 m from the cam's pivot"),
        (lambda m: m.update(crank="tappet"), "the crank 'tappet' must turn about one revolute joint"),
        (
            lambda m: m["joints"]["K"].update(
                law={"angle_deg": [0.0, 90.0, 180.0, 270.0, 300.0], "lift": [0.0, 0.004, 0.008, 0.004]}
            ),
            "law: angle_deg has 5 entries but the values have 4",
        ),
        (
            lambda m: m["joints"]["K"].update(
                law={"angle_deg": [0.0, 90.0, 180.0, 270.0], "lift": [0.0, 0.004, -0.001, 0.004]}
            ),
            "the follower table's lift has -0.001 < 0",
        ),
    ],
)
def test_bad_cam_pairs_are_refused_naming_what_is_wrong(change, expected):
    """Refused when the scene is read or, for what needs the cam's kinematics, when it becomes a machine."""
    with pytest.raises(SceneError) as error:
        build_model(validate_scene(cam_scene(change)))
    assert expected in str(error.value)


def test_an_oscillating_followers_generated_reduction_is_the_general_solvers_and_the_cams(tmp_path):
    """Source 001's rocking roller follower with weights and a roller inertia: the generated reduction (both paths'
    code) equals flat.py's to 1e-12 and the cam's own J_f = (I_O2 + m_roller l^2 + I_roller) s'^2, weight and spring
    moments (the cam link weighs nothing)."""
    from mech_regulator.mechanisms import build_reduced, cam_pairs_of, mechanism_geometry
    from mech_regulator.mechanisms.linkage import make_reduced

    scene = tmp_path / "rocking.yaml"
    scene.write_text(
        SOURCE_001_CAM.replace("mass: 0.05}", "mass: 0.05, inertia: 1.0e-5}").replace(
            "  inertia: 0.01\n", "  inertia: 0.01\n  gravity: [0.0, -9.81]\n"
        ),
        encoding="utf-8",
    )
    machine = load_scene(str(scene)).machine
    generated = build_reduced(machine.mechanism, machine.gravity)
    general = make_reduced(*mechanism_geometry(machine.mechanism), machine.gravity)
    (pair,) = cam_pairs_of(machine.mechanism, machine.gravity)
    assert pair.generalised_mass == pytest.approx(2.5e-4 + 0.3 * 0.05**2 + 0.05 * 0.1**2 + 1e-5, rel=1e-12)
    for phi in np.linspace(0.1, 2 * math.pi - 0.1, 23):
        values = generated(phi)
        assert general(phi) == pytest.approx(values, rel=1e-12, abs=1e-15)
        J, dJ, weight, spring = (float(part[0]) for part in pair.reduced(phi))
        assert values[:3] == pytest.approx((J, dJ, weight + spring), rel=1e-12, abs=1e-15)


def test_the_valve_gear_is_recorded_and_its_kinematics_print_the_cam(tmp_path, capsys):
    code, out, _ = run_cli(capsys, "kinematics", "valve_gear")
    assert code == 0 and "no joint reactions: the cam pair K's contact is not in the kinetostatics" in out
    assert "the follower jumps above 587.822 rad/s" in out
    record = tmp_path / "valve.rrd"
    code, _, err = run_cli(
        capsys,
        "simulate",
        "valve_gear",
        "--set",
        "solver.path=reference",
        "--set",
        "scenario.duration=0.005",
        "--record",
        str(record),
    )
    assert code == 0 and record.stat().st_size > 0, err


def test_a_flat_faced_follower_has_no_pressure_angle_and_its_profile_radius_is_R_plus_s_plus_s_second():
    """A flat face across the guide: alpha = 0, the profile's radius of curvature h + h'' = R + s + s'' (theory
    §5.7), the contact at the face's distance R + s from the pivot along the guide, s' across it; a knife edge's
    profile is its pitch curve, at R + s from the pivot on a centred follower."""
    law = rise_dwell_return("cycloidal")
    flat = translating_pair(law, contact="flat_face", base=0.03)
    phi = np.linspace(0.0, 2 * math.pi, 73)
    s, ds, dds = law.evaluate(phi)
    assert list(flat.pressure_angle(phi)) == [0.0] * len(phi)
    assert flat.profile_radius(phi) == pytest.approx(0.03 + s + dds, rel=1e-12)
    contact = flat.contact_point(phi)
    assert (contact.imag, contact.real) == (pytest.approx(0.03 + s, rel=1e-12), pytest.approx(ds, abs=1e-15))
    knife = translating_pair(law, contact="knife_edge", base=0.03)
    assert np.abs(knife.profile(73)) == pytest.approx(
        0.03 + law.evaluate(np.linspace(0, 2 * math.pi, 73, endpoint=False))[0], rel=1e-12
    )


@pytest.mark.parametrize("path", ["reference", "fast"])
def test_a_jump_is_found_at_the_same_time_checked_in_chunks_and_streamed_as_checked_whole(monkeypatch, path):
    """valve_gear driven past its jump speed (the motor's no-load speed 1000 rad/s: contact lost after some 60 steps):
    checked 5 steps at a time (the fast path: after each compiled call, made 4 steps long) while a stream drops the
    oldest steps (20 kept, 10 a chunk), and checked once at the load piece's end, the run ends at the same time, where
    the contact was lost, with the one event and the same message; the streamed run had dropped steps before it."""
    monkeypatch.setattr(compiled_run, "MAX_STEPS_PER_CALL", 4)  # else one call holds the run to its jump
    scene = load_scene(
        "valve_gear", [f"solver.path={path}", "scenario.duration=0.1", "machine.drive.no_load_speed=1000"]
    )
    runs = {}
    for chunk in (5, 10**9):
        monkeypatch.setattr(cam_contact, "CHECK_CHUNK_STEPS", chunk)
        monkeypatch.setattr(stream, "RETAINED_STEPS", 20 if chunk == 5 else 10**9)
        monkeypatch.setattr(stream, "BALANCE_CHUNK_STEPS", 10)
        monkeypatch.setattr(energy, "BALANCE_CHUNK_STEPS", 10)
        model = build_model(scene)
        runs[chunk] = simulate(model, stream=RunDigest(model).take)
    chunked, whole = runs[5], runs[10**9]
    assert chunked.steps_dropped > 0 and whole.steps_dropped == 0
    assert whole.status == chunked.status == "failed" and chunked.message == whole.message
    ((t_lost, what),) = chunked.events
    assert what == "contact lost at cam pair K" and chunked.events == whole.events
    assert chunked.t_end == pytest.approx(whole.t_end, rel=1e-12) and t_lost == chunked.t_end
    assert 0.0 < t_lost < 0.1 and chunked.stats.steps < whole.stats.steps  # found in its chunk, not at the end


def test_the_contact_check_does_not_depend_on_the_stretch_s_length():
    """valve_gear above its jump speed, one load piece stepped without a check: its contact is lost at the same time,
    to the last bit, when the stretch checked is the piece (0.01 s) and when it goes on with a step 100 s long (a
    central difference a millionth of the stretch wide gave another time)."""
    model = build_model(
        load_scene("valve_gear", ["solver.path=reference", "scenario.duration=0.01", "scenario.initial.omega=700"])
    )
    found = []
    for extra in (0.0, 100.0):
        stretch = Trajectory(method="DOP853", t_start=0.0)
        y, _ = _segment(model, None, 0.0, 0.01, model.initial_state(), None, stretch, None)
        if extra:
            stretch.add_piece(0.01, 0.01 + extra, lambda t, end=y: np.multiply.outer(end, np.ones(np.shape(t))))
        state = check_contact(model, stretch, 0.0, y)
        assert stretch.status == "failed" and stretch.t_end < 0.01
        found.append((stretch.t_end, stretch.message, tuple(state)))
    assert found[0] == found[1]


def test_the_co_simulation_s_exchange_steps_find_the_jump_the_monolithic_run_finds():
    """valve_gear above its jump speed co-simulated in process (exchange steps of 0.5 ms, each stretch checked as it
    is stepped: solvers/cosim.py) fails with the monolithic run's message: the same time, crank angle and speed."""
    model = build_model(
        load_scene("valve_gear", ["solver.path=reference", "scenario.duration=0.01", "scenario.initial.omega=700"])
    )
    monolithic, exchanged = simulate(model), cosimulate(model, 0.0005)
    assert exchanged.status == monolithic.status == "failed" and exchanged.message == monolithic.message


def test_a_cut_drops_the_events_and_modes_recorded_after_it():
    """Trajectory.cut at 1.5 s of a run to 2 s: the events and modes after 1.5 s are gone, those up to it kept."""
    trajectory = Trajectory(method="RK4", t_start=0.0)
    for start in (0.0, 1.0):
        trajectory.add_piece(start, start + 1.0, lambda t: np.vstack([np.asarray(t), np.ones(np.shape(t))]))
    trajectory.events += [(0.5, "a"), (1.5, "b"), (1.75, "c")]
    trajectory.modes += [(0.0, ("low",)), (1.5, ("high",)), (1.75, ("low",))]
    trajectory.cut(1.5)
    assert trajectory.t_end == 1.5 and trajectory.events == [(0.5, "a"), (1.5, "b")]
    assert trajectory.modes == [(0.0, ("low",)), (1.5, ("high",))]


def test_the_fast_path_stops_at_the_same_jump_as_the_reference_path():
    """Both paths run the same generated reduction and the same contact check: the jump above the spring's speed
    is found at the same time (to the solvers' tolerance) and reported the same way."""
    times = {}
    for path in ("reference", "fast"):
        model = build_model(
            load_scene("valve_gear", [f"solver.path={path}", "scenario.duration=0.01", "scenario.initial.omega=700"])
        )
        trajectory = simulate(model)
        assert trajectory.status == "failed" and trajectory.events[-1][1] == "contact lost at cam pair K"
        times[path] = trajectory.t_end
    assert times["fast"] == pytest.approx(times["reference"], rel=1e-6)


def test_a_cam_behind_a_coupling_is_refused():
    data = load_scene("two_mass").model_dump(exclude_none=True)
    data["machine"]["coupling"]["driven"]["mechanism"] = load_scene("valve_gear").model_dump(exclude_none=True)[
        "machine"
    ]["mechanism"]
    with pytest.raises(SceneError, match="a cam behind a coupling is not supported yet"):
        build_model(validate_scene(data))


def test_a_table_law_in_a_scene_is_analysed_like_its_segments(capsys, tmp_path):
    """The valve gear with cycloidal segments (s'' continuous), and the same law as a table of 360 points (every
    degree): the table's spline gives the same lift and jump speed to 1e-3. (Through a law whose s'' jumps, as the
    harmonic's, a cubic spline overshoots s'' near the jump, and the table's jump speed is lower.)"""
    cycloidal = cam_scene(
        lambda m: [part.update(law="cycloidal") for part in m["joints"]["K"]["law"] if part["motion"] != "dwell"]
    )
    law = linkage_core(validate_scene(cycloidal).machine.mechanism).joint("K").cam.law
    angles = np.linspace(0.0, 360.0, 361)[:-1]
    table = copy.deepcopy(cycloidal)
    table["machine"]["mechanism"]["joints"]["K"]["law"] = {
        "angle_deg": list(angles),
        "lift": list(law.evaluate(np.radians(angles))[0]),
    }
    found = []
    for data in (cycloidal, table):
        path = tmp_path / "scene.yaml"
        path.write_text(json.dumps(data), encoding="utf-8")
        code, out, _ = run_cli(capsys, "structure", str(path), "--json")
        assert code == 0
        found.append(json.loads(out)["cams"][0])
    assert found[1]["lift"] == pytest.approx(found[0]["lift"], rel=1e-3)
    assert found[1]["jump_speed"] == pytest.approx(found[0]["jump_speed"], rel=1e-3)


def test_a_cam_on_a_bull_gear_adds_its_followers_share_to_the_geared_linkages_reduction():
    """Cams and gears in one linkage: geared_shaker's bull gear (the crank) also lifts a roller tappet. Its
    generated reduction (both paths' code) equals flat.py's to 1e-12, and is the geared shaker's own plus the cam
    follower's J_f, dJ_f/dphi and weight and spring moments (docs/theory.md §5.5, §5.7)."""
    from mech_regulator.mechanisms import build_reduced, cam_pairs_of, mechanism_geometry
    from mech_regulator.mechanisms.linkage import make_reduced

    data = copy.deepcopy(load_scene("geared_shaker").model_dump(exclude_none=True))
    data["machine"]["gravity"] = [0.0, -9.81]
    mechanism = data["machine"]["mechanism"]
    mechanism["frame"]["T"] = [0.0, 0.0]
    mechanism["links"].update(
        tappet={"points": {"T": [0.0, 0.0], "R": [0.0, 0.0]}, "mass": 0.5, "centre": [0.0, 0.05]},
        roller={"points": {"R": [0.0, 0.0]}, "mass": 0.05},
    )
    mechanism["joints"].update(
        T={"type": "prismatic", "links": ["frame", "tappet"], "direction_deg": 90.0},
        R={"type": "revolute", "links": ["tappet", "roller"]},
        K={
            "type": "cam",
            "links": ["bull_gear", "roller"],
            "contact": "roller",
            "roller_radius": 0.01,
            "base_radius": 0.05,
            "spring": {"stiffness": 2000.0, "preload": 50.0},
            "law": [
                {"motion": "rise", "law": "cycloidal", "angle_deg": 120.0, "lift": 0.02},
                {"motion": "dwell", "angle_deg": 60.0},
                {"motion": "return", "law": "cycloidal", "angle_deg": 120.0, "lift": 0.02},
                {"motion": "dwell", "angle_deg": 60.0},
            ],
        },
    )
    machine = validate_scene(data).machine
    assert [group.kind for group in mechanism_geometry(machine.mechanism)[1].groups] == ["cam follower", "gear", "RRP"]
    generated = build_reduced(machine.mechanism, machine.gravity)
    general = make_reduced(*mechanism_geometry(machine.mechanism), machine.gravity)
    shaker = load_scene("geared_shaker").machine.mechanism
    geared = build_reduced(shaker, (0.0, -9.81))
    (pair,) = cam_pairs_of(machine.mechanism, machine.gravity)
    for phi in np.linspace(0.1, 2 * math.pi - 0.1, 17):
        values = generated(phi)
        assert general(phi) == pytest.approx(values, rel=1e-12, abs=1e-12)
        J, dJ, weight, spring = (float(part[0]) for part in pair.reduced(phi))
        J0, dJ0, weight0, q, dq = geared(phi)
        assert values == pytest.approx((J0 + J, dJ0 + dJ, weight0 + weight + spring, q, dq), rel=1e-12, abs=1e-12)
