"""Tests of the general planar linkage (mech_regulator.mechanisms.linkage, docs/linkages.md).

Structure: source 001's worked degree-of-freedom examples (the four-bar, the triangle of three sliders with one
repeated constraint, the parallelogram with a redundant link, the cam follower's roller with a passive freedom and its group),
the decomposition into class-II groups and its refusals.
Kinematics: each dyad type's position against a closed form (RRR: the four-bar module, RRP: the crank-slider
module, RPR: the slotted lever's angle, PRP: two lines' intersection, RPP: the Scotch yoke x = r cos phi), its
velocity and acceleration ratios against finite differences of its positions (five-point stencil, step 1e-3:
truncation h^4/30 |f^(5)| ~ 1e-13 and rounding ~ eps / h ~ 1e-13 for these O(1) linkages, so 1e-9 leaves a
margin of ~1e3 while a wrong term is O(0.1..1)); a six-bar's J(phi) against an independent loop closure solved
by Newton (scipy's fsolve) and differentiated numerically. The RRR and RRP linkages are the presets' (mechanisms/
presets.py), which test_presets.py checks against the preset mechanisms.
Kinetostatics: the balancing moment from the reactions by groups equals the reduced moment.
"""

from __future__ import annotations

import cmath
import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.optimize import fsolve

from mech_regulator.mechanisms import crank_slider, four_bar, presets
from mech_regulator.mechanisms.linkage import (
    Joint,
    Link,
    Linkage,
    LinkageError,
    analyse,
    assembly_failures,
    checked,
    make_reduced,
    solve,
)
from mech_regulator.mechanisms.linkage.groups import _rows
from mech_regulator.mechanisms.linkage.kinetostatics import make_kinetostatics

H = 1e-3
ANGLES = np.linspace(0.0, 2.0 * math.pi, 13)[:-1] + 0.137
GRAVITY = (0.7, -9.81)


def revolute(name, first, second):
    return Joint(name, "revolute", (first, second))


def prismatic(name, guide, slider, direction=0.0, slider_angle=0.0):
    return Joint(name, "prismatic", (guide, slider), direction, slider_angle)


def four_bar_linkage(a=1.0, b=3.0, c=2.5, d=3.5, th1=0.3, branch=1):
    """The preset four-bar (presets.four_bar_linkage: crank, coupler, rocker; joints crank_bearing A, crank_pin B,
    rocker_pin C, rocker_bearing D) with masses on every link and a coupler point P; branch +1 is 'open'."""
    linkage = presets.four_bar_linkage(
        four_bar.FourBarGeometry(a, b, c, d, th1, -float(branch), 2.0, 0.4, 3.0, 1.2, 0.7, 1.5, 1.0, 0.3)
    )
    return replace(
        linkage,
        links=tuple(
            replace(link, points={**link.points, "P": 1.0 + 0.8j}) if link.name == "coupler" else link
            for link in linkage.links
        ),
        points=linkage.points + ("P",),
    )


def crank_slider_linkage(R=0.1, rod=0.35, e=0.03):
    """The preset crank-slider (presets.crank_slider_linkage): the piston on the frame's line y = e along +x (RRP
    group)."""
    return presets.crank_slider_linkage(crank_slider.CrankSliderGeometry(R, rod, e, 1.2, 0.03, 2.5, 0.12, 0.04, 1.7))


def slotted_lever_linkage(r=0.3, d=0.8, offset=0.05, branch=1):
    """A shaper's slotted lever (RPR group): the block pinned at the crank pin B slides in the lever's slot, a line
    `offset` beside the lever's axis through its pivot O = (0, -d)."""
    return Linkage(
        links=(
            Link("frame", {"A": 0j, "O": -1j * d}),
            Link("crank", {"A": 0j, "B": r + 0j}),
            Link("block", {"B": 0j, "S": 0j}, mass=0.5, centre=0.01 + 0j, inertia=0.001),
            Link("lever", {"O": 0j, "S": complex(0.0, offset), "T": 1.5 + 0j}, mass=4.0, centre=0.6 + 0j, inertia=0.5),
        ),
        joints=(
            revolute("A", "frame", "crank"),
            revolute("B", "crank", "block"),
            prismatic("S", "lever", "block"),
            revolute("O", "frame", "lever"),
        ),
        frame="frame",
        crank="crank",
        branches={"S": branch},
        points=("T",),
        output_link="lever",
    )


def crank_line_linkage(x0=0.6):
    """A PRP group: a sleeve slides along the crank's line and is pinned at C to a block on the frame's vertical
    guide x = x0, so C = x0 + i x0 tan(phi)."""
    return Linkage(
        links=(
            Link("frame", {"A": 0j, "G": complex(x0, 0.0)}),
            Link("crank", {"A": 0j, "S": 0j}, mass=1.0, centre=0.2 + 0j, inertia=0.01),
            Link("sleeve", {"S": 0j, "C": 0j}, mass=0.4, centre=0.02 + 0j, inertia=0.002),
            Link("block", {"C": 0j, "G": 0j}, mass=0.9, centre=0.01j, inertia=0.003),
        ),
        joints=(
            revolute("A", "frame", "crank"),
            prismatic("S", "crank", "sleeve"),
            revolute("C", "sleeve", "block"),
            prismatic("G", "frame", "block", direction=math.pi / 2),
        ),
        frame="frame",
        crank="crank",
        output_joint="G",
    )


def scotch_yoke_linkage(r=0.25):
    """An RPP group: the block pinned at the crank pin B slides in the yoke's vertical slot; the yoke slides on
    the frame's horizontal guide: x_yoke = r cos(phi)."""
    return Linkage(
        links=(
            Link("frame", {"A": 0j, "Y": 0j}),
            Link("crank", {"A": 0j, "B": r + 0j}),
            Link("block", {"B": 0j, "K": 0j}, mass=0.3, centre=0.01 + 0j, inertia=0.001),
            Link("yoke", {"K": 0j, "Y": 0j}, mass=5.0, centre=0.1 + 0.05j, inertia=0.2),
        ),
        joints=(
            revolute("A", "frame", "crank"),
            revolute("B", "crank", "block"),
            prismatic("K", "yoke", "block", direction=math.pi / 2),
            prismatic("Y", "frame", "yoke"),
        ),
        frame="frame",
        crank="crank",
        output_joint="Y",
    )


def turned_block_linkage():
    """The slotted lever with a block turned by slider_angle 0.4 rad to the lever and its sliding point S off its
    pin B (RPR with the offset term (p_s[S] - p_s[B]) e^{i alpha})."""
    base = slotted_lever_linkage()
    return Linkage(
        links=base.links[:2]
        + (Link("block", {"B": 0j, "S": 0.02 + 0.01j}, mass=0.5, centre=0.01 + 0j, inertia=0.001),)
        + base.links[3:],
        joints=base.joints[:2] + (prismatic("S", "lever", "block", slider_angle=0.4),) + base.joints[3:],
        frame="frame",
        crank="crank",
        points=("T",),
        output_link="lever",
    )


def sliding_sleeve_linkage():
    """An RRP group whose prismatic joint has its guide on the group's link: a sleeve pinned to the rod at C slides
    over the frame's fixed point G (the sleeve is the guide, the frame the slider), so theta_sleeve = -alpha."""
    return Linkage(
        links=(
            Link("frame", {"A": 0j, "G": 0.3 + 0j}),
            Link("crank", {"A": 0j, "B": 0.1 + 0j}, mass=1.0, centre=0.05 + 0j, inertia=0.002),
            Link("rod", {"B": 0j, "C": 0.35 + 0j}, mass=2.0, centre=0.15 + 0.02j, inertia=0.03),
            Link("sleeve", {"C": 0.05j, "G": 0j}, mass=1.5, centre=0.1 + 0j, inertia=0.01),
        ),
        joints=(
            revolute("A", "frame", "crank"),
            revolute("B", "crank", "rod"),
            revolute("C", "rod", "sleeve"),
            prismatic("G", "sleeve", "frame", slider_angle=0.2),
        ),
        frame="frame",
        crank="crank",
        output_joint="G",
    )


DYADS = {
    "RRR": four_bar_linkage,
    "RRP": crank_slider_linkage,
    "RPR": slotted_lever_linkage,
    "PRP": crank_line_linkage,
    "RPP": scotch_yoke_linkage,
    "RPR-turned": turned_block_linkage,
    "RRP-moving-guide": sliding_sleeve_linkage,
}


# ----------------------------------------------------------------------------------------------
# Structure (source 001, chapter 1)


def test_four_bar_has_one_freedom_and_one_rrr_group():
    structure = analyse(four_bar_linkage())
    assert (structure.moving_links, structure.lower_pairs, structure.higher_pairs, structure.freedom) == (3, 4, 0, 1)
    assert [group.kind for group in structure.groups] == ["RRR"]
    assert structure.refusal() is None


def test_triangle_of_three_sliders_has_one_repeated_constraint():
    """Source 001, fig. 1.23: links 1 and 2 and the frame 3 joined by three prismatic joints: n = 2, p5 = 3,
    R_repeated = 1, W = 3*2 - (2*3 - 1) = 1 (no crank: the count only)."""
    linkage = Linkage(
        links=(
            Link("3", {"A": 0j, "C": 1 + 0j}),
            Link("1", {"A": 0j, "B": 0.5 + 0.5j}),
            Link("2", {"C": 0j, "B": -0.5 + 0.5j}),
        ),
        joints=(
            prismatic("A", "3", "1"),
            prismatic("C", "3", "2", direction=2.0),
            prismatic("B", "1", "2", direction=1.0),
        ),
        frame="3",
        crank=None,
    )
    structure = analyse(linkage)
    assert (structure.moving_links, structure.lower_pairs, len(structure.repeated)) == (2, 3, 1)
    assert structure.freedom == 1
    assert "links 3, 1, 2 form a triangle of prismatic joints A, C, B" in structure.repeated[0]


def test_no_crank_and_no_gear_data_are_refused_by_name():
    """A linkage built for the count only has no crank to pivot about, a lower pair no gear data: asked for them
    (Linkage.driving_crank, Joint.gear_mesh), they raise LinkageError saying what is missing."""
    linkage = replace(four_bar_linkage(), crank=None)
    with pytest.raises(LinkageError, match="the linkage has no crank; expected a driving link"):
        linkage.crank_pivot()
    joint = linkage.joints[0]
    with pytest.raises(LinkageError, match=rf"the joint '{joint.name}' \(revolute\) has no gear data"):
        joint.gear_mesh()


def test_parallelogram_with_an_extra_link_has_one_redundant_constraint():
    """Source 001, fig. 1.26: the parallelogram A B C D (link 1 = AB, 2 = BCE, 3 = DC) with the link 5 = EF,
    l_AB = l_CD = l_EF, l_AF = l_BE, l_BC = l_AD: 4 links and 6 revolute joints of it give 3*4 - 2*6 = 0, yet it
    moves: EF is one redundant constraint. Link 1 rocks here, driven by a crank-rocker (crank O K, rod K B1), so the
    parallelogram never reaches its change points (at AB along AD it could fold into an antiparallelogram):
    n = 6, p5 = 9, R_redundant = 1, W = 3*6 - (2*9 - 1) = 1. With EF longer it is a structure (W = 0)."""
    structure = analyse(parallelogram_linkage(1.0))
    assert (structure.moving_links, structure.lower_pairs, len(structure.redundant)) == (6, 9, 1)
    assert structure.freedom == 1 and structure.refusal() is None
    assert [group.kind for group in structure.groups] == ["RRR", "RRR", "redundant link"]
    for phi in ANGLES:
        poses = solve(parallelogram_linkage(1.0), structure, phi)
        assert 0.0 < poses["1"][1] < math.pi
        assert (poses["5"][1], poses["5"][3], poses["5"][5]) == pytest.approx(
            (poses["1"][1], poses["1"][3], poses["1"][5]), abs=1e-12
        )  # EF stays parallel to AB
    wrong = analyse(parallelogram_linkage(1.1))
    assert wrong.freedom == 0 and "W = 3*6 - (2*9 + 0 - 0 - 0) - 0 = 0" in wrong.refusal()


def test_cam_follower_roller_has_one_passive_freedom():
    """Source 001, fig. 1.27: cam 1, roller 2, rocking follower 3: n = 3, p5 = 3, p4 = 1, W_passive = 1,
    W = 3*3 - (2*3 + 1) - 1 = 1; the follower 3 with its roller 2 is one cam follower group (3*2 - 2*2 - 1 - 1 = 0)."""
    linkage = Linkage(
        links=(
            Link("0", {"O1": 0j, "O2": 2 + 0j}),
            Link("1", {"O1": 0j}),
            Link("2", {"R": 0j}, roller_radius=0.1),
            Link("3", {"O2": 0j, "R": -1 + 0.5j}),
        ),
        joints=(
            revolute("O1", "0", "1"),
            Joint("K", "cam", ("1", "2")),
            revolute("R", "2", "3"),
            revolute("O2", "0", "3"),
        ),
        frame="0",
        crank="1",
    )
    structure = analyse(linkage)
    assert (structure.moving_links, structure.lower_pairs, structure.higher_pairs) == (3, 3, 1)
    assert len(structure.passive) == 1 and "roller 2" in structure.passive[0]
    assert structure.freedom == 1
    assert structure.refusal() is None
    (group,) = structure.groups
    assert (group.kind, group.follower, group.roller, group.guide.name, group.roller_joint.name) == (
        "cam follower",
        "3",
        "2",
        "O2",
        "R",
    )
    assert (
        "group 1: cam follower 3 (cam pair K) (links 3 + 2, joints O2 (revolute), K (cam), R (revolute))"
        in structure.report()
    )


def test_a_class_three_group_is_named_and_refused():
    """A ternary link T joined to three binary links X, Y, Z pinned to the crank and the frame: n = 5, p5 = 7,
    W = 1, but the four links form one class-III group, which is not supported."""
    linkage = Linkage(
        links=(
            Link("frame", {"A": 0j, "E": 3 + 0j, "F": 1.5 - 2j}),
            Link("crank", {"A": 0j, "B": 0.5 + 0j}),
            Link("X", {"B": 0j, "G": 1.5 + 0j}),
            Link("Y", {"E": 0j, "H": 1.5 + 0j}),
            Link("Z", {"F": 0j, "K": 1.5 + 0j}),
            Link("T", {"G": 0j, "H": 1 + 0j, "K": 0.5 - 0.8j}),
        ),
        joints=(
            revolute("A", "frame", "crank"),
            revolute("B", "crank", "X"),
            revolute("E", "frame", "Y"),
            revolute("F", "frame", "Z"),
            revolute("G", "X", "T"),
            revolute("H", "Y", "T"),
            revolute("K", "Z", "T"),
        ),
        frame="frame",
        crank="crank",
    )
    structure = analyse(linkage)
    assert structure.freedom == 1
    with pytest.raises(LinkageError, match=r"\['X', 'Y', 'Z', 'T'\].*class III or higher"):
        checked(linkage)


def test_a_joint_naming_an_unknown_link_is_refused():
    linkage = four_bar_linkage()
    broken = Linkage(
        links=linkage.links,
        joints=linkage.joints[:-1] + (revolute("rocker_bearing", "frame", "rocket"),),
        frame="frame",
        crank="crank",
    )
    with pytest.raises(LinkageError, match="joint 'rocker_bearing' names the link 'rocket'"):
        analyse(broken)


def test_a_group_that_cannot_assemble_is_located_on_the_crank_angle():
    """A non-Grashof four-bar (a + d > b + c): the RRR group rocker_pin fails where |B - D| > b + c, i.e. around
    phi = 180 deg (th1 = 0): cos(psi) <= (a^2 + d^2 - (b + c)^2) / (2 a d)."""
    linkage = four_bar_linkage(a=1.5, b=2.0, c=2.0, d=3.0, th1=0.0)
    half = math.degrees(math.acos((1.5**2 + 3.0**2 - 4.0**2) / (2 * 1.5 * 3.0)))
    [failure] = assembly_failures(linkage, checked(linkage))
    assert "RRR group rocker_pin" in failure
    span = failure.split("crank angles ")[1].split(" deg")[0]
    low, high = (float(value) for value in span.split(" to "))
    assert half < low < half + 0.5 and 360.0 - half - 0.5 < high < 360.0 - half
    with pytest.raises(LinkageError, match="RRR group rocker_pin .* at crank angle 180.000 deg cannot be assembled"):
        solve(linkage, checked(linkage), math.pi)


# ----------------------------------------------------------------------------------------------
# Dyads: positions against closed forms, derivatives against finite differences


def _residuals(linkage, poses):
    """The joints' constraint values at these poses (zero when assembled)."""
    values = []
    for joint in linkage.joints:
        a, b = joint.links
        Pa = poses[a][0] + linkage.link(a).points[joint.name] * cmath.exp(1j * poses[a][1])
        Pb = poses[b][0] + linkage.link(b).points[joint.name] * cmath.exp(1j * poses[b][1])
        if joint.kind == "revolute":
            values += [abs(Pa - Pb)]
        else:
            w = cmath.exp(1j * (joint.direction + poses[a][1]))
            values += [
                ((Pb - Pa) * w.conjugate()).imag,
                math.remainder(poses[b][1] - poses[a][1] - joint.slider_angle, 2 * math.pi),
            ]
    return values


@pytest.mark.parametrize("kind", list(DYADS))
def test_dyad_positions_satisfy_every_joint_and_their_closed_form(kind):
    linkage = DYADS[kind]()
    structure = checked(linkage)
    assert [group.kind for group in structure.groups] == [kind[:3]]
    for phi in ANGLES:
        if kind == "PRP" and abs(math.cos(phi)) < 0.2:
            continue
        poses = solve(linkage, structure, phi, derivatives=False)
        assert max(map(abs, _residuals(linkage, poses))) < 1e-12
        if kind == "RRR":
            th4 = four_bar.link_angles(phi, 1.0, 3.0, 2.5, 3.5, 0.3, four_bar.BRANCH_SIGN["open"])[3]
            assert math.remainder(poses["rocker"][1] - th4, 2 * math.pi) == pytest.approx(0.0, abs=1e-12)
        elif kind == "RRP":
            x = crank_slider.slider_kinematics(phi, 0.1, 0.35, 0.03)[0]
            assert poses["piston"][0] == pytest.approx(complex(x, 0.03), abs=1e-14)
        elif kind == "RPR":
            B, O = 0.3 * cmath.exp(1j * phi), -0.8j
            # the crank pin is `offset` beside the lever's axis, on the side the slot is: angle = arg(B - O) - asin
            expected = cmath.phase(B - O) - math.asin(0.05 / abs(B - O))
            assert math.remainder(poses["lever"][1] - expected, 2 * math.pi) == pytest.approx(0.0, abs=1e-12)
        elif kind == "PRP":
            assert poses["block"][0] == pytest.approx(complex(0.6, 0.6 * math.tan(phi)), abs=1e-12)
        elif kind == "RPP":
            assert poses["yoke"][0] == pytest.approx(0.25 * math.cos(phi), abs=1e-14)
        elif kind == "RRP-moving-guide":  # the sleeve keeps -alpha; its line through C passes through G
            C = 0.1 * cmath.exp(1j * phi) + 0.35 * cmath.exp(1j * poses["rod"][1])
            assert poses["sleeve"][1] == pytest.approx(-0.2, abs=1e-15)
            assert ((C - 0.05j * cmath.exp(-0.2j) - 0.3) * cmath.exp(0.2j)).imag == pytest.approx(0.0, abs=1e-14)


def test_branches_are_the_two_assemblies():
    """RRR: +1 puts C left of B -> D (the four-bar's 'open'), -1 right ('crossed'); RPR: -1 turns the lever by
    pi - 2 asin(h / rho) from +1 (the other root)."""
    phi = 0.8
    for branch, name in ((1, "open"), (-1, "crossed")):
        linkage = four_bar_linkage(branch=branch)
        th4 = four_bar.link_angles(phi, 1.0, 3.0, 2.5, 3.5, 0.3, four_bar.BRANCH_SIGN[name])[3]
        rocker = solve(linkage, checked(linkage), phi)["rocker"][1]
        assert math.remainder(rocker - th4, 2 * math.pi) == pytest.approx(0.0, abs=1e-12)
    plus, minus = (
        solve(slotted_lever_linkage(branch=b), checked(slotted_lever_linkage(branch=b)), phi)["lever"][1]
        for b in (1, -1)
    )
    rho = abs(0.3 * cmath.exp(1j * phi) + 0.8j)
    assert math.remainder(plus - minus - (math.pi - 2 * math.asin(0.05 / rho)), 2 * math.pi) == pytest.approx(
        0.0, abs=1e-12
    )


def _stencil(values):
    """Five-point central difference of samples at phi - 2h, phi - h, phi + h, phi + 2h."""
    return (values[0] - 8.0 * values[1] + 8.0 * values[2] - values[3]) / (12.0 * H)


@pytest.mark.parametrize("kind", list(DYADS))
def test_dyad_velocity_and_acceleration_ratios_match_finite_differences(kind):
    """r', theta' against the differences of r, theta; r'', theta'' against the differences of r', theta'."""
    linkage = DYADS[kind]()
    structure = checked(linkage)
    for phi in ANGLES[::2]:
        if kind == "PRP" and abs(math.cos(phi)) < 0.3:
            continue
        poses = solve(linkage, structure, phi)
        around = [solve(linkage, structure, phi + k * H) for k in (-2, -1, 1, 2)]
        for name in linkage.moving_links():
            for index in (0, 1, 2, 3):
                samples = [pose[name][index] for pose in around]
                if index == 1:
                    samples = [poses[name][1] + math.remainder(s - poses[name][1], 2 * math.pi) for s in samples]
                expected = _stencil(samples)
                scale = max(1.0, abs(expected))
                assert abs(poses[name][index + 2] - expected) < 1e-9 * scale, (name, index, phi)


# ----------------------------------------------------------------------------------------------
# Reduction to the crank


def parallelogram_linkage(ef_length: float = 1.0):
    """Source 001, fig. 1.26: the parallelogram A B C D (link 1 = AB, 2 = BCE, 3 = DC) with the link 5 = EF (a
    redundant link at ef_length 1), link 1 rocked by a crank-rocker (crank O K, rod K B1)."""
    return Linkage(
        links=(
            Link("0", {"O": 0.9 + 0j, "A": 0j, "D": 2 + 0j, "F": 1 + 0j}),
            Link("crank", {"O": 0j, "K": 0.2 + 0j}),
            Link("rod", {"K": 0j, "B1": 0.9 + 0j}),
            Link("1", {"A": 0j, "B": 1 + 0j, "B1": 0.5 + 0j}),
            Link("2", {"B": 0j, "C": 2 + 0j, "E": 1 + 0j}),
            Link("3", {"D": 0j, "C": 1 + 0j}),
            Link("5", {"F": 0j, "E": ef_length + 0j}),
        ),
        joints=(
            revolute("O", "0", "crank"),
            revolute("K", "crank", "rod"),
            revolute("B1", "rod", "1"),
            revolute("A", "0", "1"),
            revolute("B", "1", "2"),
            revolute("C", "2", "3"),
            revolute("D", "0", "3"),
            revolute("E", "2", "5"),
            revolute("F", "0", "5"),
        ),
        frame="0",
        crank="crank",
        branches={"B1": -1, "C": 1},
    )


def six_bar_linkage():
    """A six-bar press: the four-bar's coupler point P drives, through the rod P-F, a ram F on the frame's
    vertical guide x = 1.2 (RRR then RRP)."""
    base = four_bar_linkage()
    return Linkage(
        links=(Link("frame", {**base.links[0].points, "G": 1.2 + 0j}),)
        + base.links[1:]
        + (
            Link("rod", {"P": 0j, "F": 2.4 + 0j}, mass=2.0, centre=1.1 + 0.1j, inertia=0.9),
            Link("ram", {"F": 0j, "G": 0j}, mass=6.0, centre=0.05j, inertia=0.2),
        ),
        joints=base.joints
        + (
            revolute("P", "coupler", "rod"),
            revolute("F", "rod", "ram"),
            prismatic("G", "frame", "ram", direction=-math.pi / 2),
        ),
        frame="frame",
        crank="crank",
        output_joint="G",
    )


def test_six_bar_reduced_inertia_matches_an_independent_loop_closure():
    """The loops B + b e^{i th3} = D + c e^{i th4} and P + e e^{i th5} = F = 1.2 + i y solved for (th3, th4, th5, y)
    by Newton (fsolve, from the previous angle's solution), their ratios by five-point differences, and
    J = sum m |S'|^2 + I th'^2 summed link by link; the frame's guide point G = 1.2 is the origin of the guide."""
    linkage = six_bar_linkage()
    structure = checked(linkage)
    assert [group.kind for group in structure.groups] == ["RRR", "RRP"]
    reduced = make_reduced(linkage, structure, None)
    D, a, b, c, e, P_local = 3.5 * cmath.exp(0.3j), 1.0, 3.0, 2.5, 2.4, 1.0 + 0.8j

    def loops(x, phi):
        th3, th4, th5, y = x
        B = a * cmath.exp(1j * phi)
        first = B + b * cmath.exp(1j * th3) - D - c * cmath.exp(1j * th4)
        P = B + P_local * cmath.exp(1j * th3)
        second = P + e * cmath.exp(1j * th5) - complex(1.2, y)
        return [first.real, first.imag, second.real, second.imag]

    def centres(phi, guess):
        x = fsolve(loops, guess, args=(phi,), xtol=1e-13)
        th3, th4, th5, y = x
        B = a * cmath.exp(1j * phi)
        P = B + P_local * cmath.exp(1j * th3)
        return x, {
            "crank": (0.4 * cmath.exp(1j * phi), phi),
            "coupler": (B + 1.2 * cmath.exp(1j * th3), th3),
            "rocker": (D + 1.0 * cmath.exp(1j * th4), th4),
            "rod": (P + (1.1 + 0.1j) * cmath.exp(1j * th5), th5),
            "ram": (complex(1.2, y) + 0.05j, 0.0),
        }

    masses = {link.name: (link.mass, link.inertia) for link in linkage.links[1:]}
    for phi in ANGLES[::3]:
        poses = solve(linkage, structure, phi)
        guess = [poses["coupler"][1], poses["rocker"][1], poses["rod"][1], poses["ram"][0].imag]
        samples = [centres(phi + k * H, guess)[1] for k in (-2, -1, 1, 2)]
        J = 0.0
        for name, (m, inertia) in masses.items():
            dS = _stencil([sample[name][0] for sample in samples])
            dth = _stencil([sample[name][1] for sample in samples])
            J += m * abs(dS) ** 2 + inertia * dth * dth
        assert reduced(phi)[0] == pytest.approx(J, rel=1e-8)
        assert reduced(phi)[3] == pytest.approx(-centres(phi, guess)[0][3], abs=1e-10)  # q: travel downwards


def test_rows_are_the_partial_derivatives_of_the_constraints():
    """The Jacobian rows used for the ratios against finite differences of the constraint values."""
    linkage = slotted_lever_linkage()
    poses = solve(linkage, checked(linkage), 0.6, derivatives=False)
    joint = linkage.joint("S")
    rows = _rows(linkage, poses, joint)
    for link in joint.links:
        for coordinate in range(3):
            shifted = []
            for step in (-1e-6, 1e-6):
                moved = {name: list(pose) for name, pose in poses.items()}
                if coordinate == 2:
                    moved[link][1] += step
                else:
                    moved[link][0] += step * (1j if coordinate else 1)
                shifted.append(_residuals(linkage, moved)[2:4])
            for row, (low, high) in zip(rows, zip(*shifted)):
                assert (high - low) / 2e-6 == pytest.approx(row[link][coordinate], abs=1e-8)


# ----------------------------------------------------------------------------------------------
# Kinetostatics by groups


@pytest.mark.parametrize(
    "build",
    [
        six_bar_linkage,
        slotted_lever_linkage,
        crank_line_linkage,
        scotch_yoke_linkage,
        crank_slider_linkage,
        turned_block_linkage,
        sliding_sleeve_linkage,
    ],
)
def test_balancing_moment_equals_the_reduced_moment(build):
    """M_b = J epsilon + 1/2 J' omega^2 - M_weight - Q q' (J with the crank's own m cg^2 + I), from the reactions
    solved group by group from the farthest inward: an independent check of the reactions and of J, J', q'."""
    linkage = build()
    structure = checked(linkage)
    loads = make_kinetostatics(linkage, structure, GRAVITY)
    reduced = make_reduced(linkage, structure, GRAVITY)
    for phi, omega, epsilon, force in ((0.4, 7.0, 30.0, 150.0), (2.2, -3.0, -12.0, -40.0), (4.9, 11.0, 0.0, 75.0)):
        J, dJ, weight, q, dq = reduced(phi)
        expected = J * epsilon + 0.5 * dJ * omega**2 - weight - force * dq
        scale = abs(J * epsilon) + abs(0.5 * dJ * omega**2) + abs(weight) + abs(force * dq)
        assert loads(phi, omega, epsilon, force).balancing == pytest.approx(expected, abs=1e-11 * scale)
