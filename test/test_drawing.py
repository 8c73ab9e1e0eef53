"""Tests of the drawing geometry (mechanisms.drawing, governors.drawing): the drawn links keep their
lengths at every angle, the slider stays on its guide, the four-bar keeps its branch, the governor's
sleeve rises by sensor.sleeve(a) and stays between its stops, and the bounds contain everything drawn.

Tolerances: the outlines are built from closed forms in double precision on lengths O(0.1 m), so
1e-12 m is far above their rounding (~1e-16 m) and far below any real error (a wrong term is O(1 mm)).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mech_regulator.governors.centrifugal import PorterSensor
from mech_regulator.governors.drawing import COLLAR_RADIUS, SLEEVE_HALF_HEIGHT, porter_sleeve_height
from mech_regulator.mechanisms.crank_slider import dead_centres
from mech_regulator.mechanisms.drawing import (
    BLOCK_HEIGHT_PER_CRANK,
    BLOCK_LENGTH_PER_CRANK,
    BOUNDS_MARGIN,
    DISC_RADIUS,
    mechanism_bounds,
    mechanism_outline,
)
from mech_regulator.scene.mechanism_keys import CrankSlider, FourBar

TOL = 1e-12
# 997 crank angles over three turns (-2 pi to 4 pi), offset so that none lies on the bounds' 360-point grid
ANGLES = np.linspace(-2.0 * math.pi, 4.0 * math.pi, 997) + 0.0123

CRANK_SLIDERS = [
    pytest.param(CrankSlider(type="crank_slider", crank=0.04, rod=0.14), id="engine"),
    pytest.param(CrankSlider(type="crank_slider", crank=0.05, rod=0.12, offset=0.02), id="offset+"),
    pytest.param(CrankSlider(type="crank_slider", crank=0.5, rod=1.6, offset=-0.3), id="offset-"),
]
FOUR_BARS = [
    pytest.param(FourBar(type="four_bar", crank=0.04, coupler=0.12, rocker=0.08, frame=0.10), id="rocker_open"),
    pytest.param(
        FourBar(type="four_bar", crank=0.04, coupler=0.12, rocker=0.08, frame=0.10, branch="crossed"),
        id="rocker_crossed",
    ),
    pytest.param(
        FourBar(type="four_bar", crank=1.0, coupler=2.6, rocker=2.2, frame=3.0, frame_angle_deg=40.0), id="tilted_frame"
    ),
]


def length(p, q) -> float:
    return float(np.hypot(*(np.asarray(q) - np.asarray(p))))


def inside(part: np.ndarray, bounds, grow: float = 0.0) -> bool:
    xmin, xmax, ymin, ymax = bounds
    points = part.reshape(-1, 2)
    return bool(
        np.all(points[:, 0] - grow >= xmin)
        and np.all(points[:, 0] + grow <= xmax)
        and np.all(points[:, 1] - grow >= ymin)
        and np.all(points[:, 1] + grow <= ymax)
    )


# --------------------------------------------------------------------------------------------
# Crank–slider


@pytest.mark.parametrize("spec", CRANK_SLIDERS)
def test_crank_slider_links_keep_their_lengths_and_the_slider_its_guide(spec):
    for phi in ANGLES:
        outline = mechanism_outline(spec, phi)
        O, B = outline["crank"]
        B_rod, C = outline["rod"]
        assert np.allclose(O, 0.0, atol=TOL)
        assert np.allclose(B, [spec.crank * math.cos(phi), spec.crank * math.sin(phi)], atol=TOL)
        assert np.array_equal(B, B_rod)  # rod hinged at the crank pin
        assert length(B, C) == pytest.approx(spec.rod, abs=TOL)
        assert C[0] > B[0]  # the slider's assembly on the +x side
        assert C[1] == pytest.approx(spec.offset, abs=TOL)  # on the line y = e
        (x0, y0), (x1, y1) = outline["guide"]
        assert y0 == y1 == pytest.approx(spec.offset, abs=TOL)
        block = outline["slider"]
        assert np.allclose(block[:4].mean(axis=0), C, atol=TOL)  # the block is centred on C
        assert np.ptp(block[:, 0]) == pytest.approx(BLOCK_LENGTH_PER_CRANK * spec.crank, abs=TOL)
        assert np.ptp(block[:, 1]) == pytest.approx(BLOCK_HEIGHT_PER_CRANK * spec.crank, abs=TOL)
        assert x0 <= block[:, 0].min() + TOL and block[:, 0].max() <= x1 + TOL  # the block never leaves the guide
        assert np.allclose(outline["joints"], [O, B, C], atol=TOL)


@pytest.mark.parametrize("spec", CRANK_SLIDERS)
def test_crank_slider_guide_spans_exactly_the_stroke_and_a_block(spec):
    """The guide reaches half a block beyond the slider at the two dead centres (crank_slider.dead_centres),
    and the slider never goes beyond them."""
    (x0, _), (x1, _) = mechanism_outline(spec, 0.0)["guide"]
    half_block = 0.5 * BLOCK_LENGTH_PER_CRANK * spec.crank
    outer, inner = dead_centres(spec.crank, spec.rod, spec.offset)
    assert x0 + half_block == pytest.approx(mechanism_outline(spec, inner)["rod"][1, 0], abs=TOL)
    assert x1 - half_block == pytest.approx(mechanism_outline(spec, outer)["rod"][1, 0], abs=TOL)
    slider_x = [mechanism_outline(spec, phi)["rod"][1, 0] for phi in ANGLES]
    assert x0 + half_block - TOL <= min(slider_x) and max(slider_x) <= x1 - half_block + TOL


# --------------------------------------------------------------------------------------------
# Four-bar


@pytest.mark.parametrize("spec", FOUR_BARS)
def test_four_bar_links_keep_their_lengths_and_branch(spec):
    th1 = math.radians(spec.frame_angle_deg)
    D_expected = [spec.frame * math.cos(th1), spec.frame * math.sin(th1)]
    for phi in ANGLES:
        outline = mechanism_outline(spec, phi)
        A, B = outline["crank"]
        B_coupler, C = outline["coupler"]
        D, C_rocker = outline["rocker"]
        assert np.allclose(A, 0.0, atol=TOL)
        assert np.allclose(D, D_expected, atol=TOL)
        assert np.allclose(outline["frame"], [A, D], atol=TOL)
        assert np.array_equal(B, B_coupler) and np.array_equal(C, C_rocker)
        assert length(A, B) == pytest.approx(spec.crank, abs=TOL)
        assert length(B, C) == pytest.approx(spec.coupler, abs=TOL)
        assert length(D, C) == pytest.approx(spec.rocker, abs=TOL)
        assert math.atan2(B[1], B[0]) == pytest.approx(math.remainder(phi, 2 * math.pi), abs=1e-12)
        # 'open' puts C to the right of the directed line D->B (negative cross product), 'crossed' to the left
        DB, DC = B - D, C - D
        side = DB[0] * DC[1] - DB[1] * DC[0]
        assert (side < 0.0) == (spec.branch == "open")
        assert np.allclose(outline["joints"], [A, B, C, D], atol=TOL)


# --------------------------------------------------------------------------------------------
# No mechanism


def test_machine_without_mechanism_draws_a_turning_spoke_on_a_disc():
    for phi in ANGLES:
        outline = mechanism_outline(None, phi)
        centre, tip = outline["spoke"]
        assert np.allclose(centre, 0.0, atol=TOL)
        assert np.allclose(tip, [DISC_RADIUS * math.cos(phi), DISC_RADIUS * math.sin(phi)], atol=TOL)
        assert np.allclose(np.hypot(*outline["disc"].T), DISC_RADIUS, atol=TOL)


# --------------------------------------------------------------------------------------------
# Mechanism bounds


@pytest.mark.parametrize("spec", [*CRANK_SLIDERS, *FOUR_BARS, pytest.param(None, id="no_mechanism")])
def test_mechanism_bounds_contain_every_outline_and_frame_it_tightly(spec):
    bounds = mechanism_bounds(spec)
    outlines = [mechanism_outline(spec, phi) for phi in ANGLES]
    for outline in outlines:
        for name, part in outline.items():
            assert inside(part, bounds), (name, bounds)
    points = np.concatenate([part.reshape(-1, 2) for outline in outlines for part in outline.values()])
    span = max(np.ptp(points[:, 0]), np.ptp(points[:, 1]))
    pad = BOUNDS_MARGIN * span
    xmin, xmax, ymin, ymax = bounds
    # no side lies further out than the margin (plus what the 360-point grid may miss: < 1e-4 span)
    assert xmin >= points[:, 0].min() - pad - 1e-4 * span and xmax <= points[:, 0].max() + pad + 1e-4 * span
    assert ymin >= points[:, 1].min() - pad - 1e-4 * span and ymax <= points[:, 1].max() + pad + 1e-4 * span


# --------------------------------------------------------------------------------------------
# Governor


def porter(**changes) -> PorterSensor:
    """engine_direct's sensor (l = 0.2 m, stroke 20..80 mm), with changes."""
    values = dict(
        ball_mass=1.0,
        arm_length=0.2,
        sleeve_mass=5.0,
        stiffness=0.0,
        free_position=0.0,
        damping=200.0,
        kinetic_friction=0.0,
        static_friction=0.0,
        ratio=0.08,
        gravity=9.81,
        stroke=(0.02, 0.08),
    )
    values.update(changes)
    return PorterSensor(**values)


SENSORS = [
    pytest.param(porter(), id="engine_direct"),
    pytest.param(porter(arm_length=0.35, ball_mass=4.0, stroke=(0.05, 0.6)), id="wide_stroke"),
]
SPINDLE_ANGLES = np.linspace(0.0, 2.0 * math.pi, 37) + 0.05


def stroke_angles(sensor: PorterSensor, count: int = 41) -> np.ndarray:
    return np.linspace(*sensor.stop_angles(), count)


@pytest.mark.parametrize("sensor", SENSORS)
def test_governor_linkage_lengths_and_sleeve_lift(sensor):
    l = sensor.arm_length
    for a in stroke_angles(sensor):
        for psi in SPINDLE_ANGLES:
            outline = sensor.outline(a, psi)
            balls = outline["balls"]
            sleeve_centre = outline["sleeve"][:4].mean(axis=0)
            for side in range(2):
                hinge, ball = outline["upper_arms"][side]
                ball_link, sleeve_end = outline["lower_links"][side]
                assert np.allclose(hinge, 0.0, atol=TOL)
                assert np.array_equal(ball, balls[side]) and np.array_equal(ball_link, balls[side])
                assert np.allclose(sleeve_end, sleeve_centre, atol=TOL)
                # the arm in the drawing plane: horizontal l sin a, vertical l cos a below the hinge
                assert abs(ball[0]) == pytest.approx(l * math.sin(a), abs=TOL)
                assert ball[1] == pytest.approx(-l * math.cos(a), abs=TOL)
                # the lower link is as long as the arm (Porter)
                assert math.hypot(*(ball - sleeve_end)) == pytest.approx(l, abs=TOL)
            assert balls[0, 0] == pytest.approx(-balls[1, 0], abs=TOL)
            assert balls[0, 0] >= 0.0  # ball 0 is the one on the +x side
            assert sleeve_centre[0] == pytest.approx(0.0, abs=TOL)
            # the sleeve's lift above its lowest possible position (arms along the spindle, centre at -2 l)
            assert sleeve_centre[1] + 2.0 * l == pytest.approx(sensor.sleeve(a), abs=TOL)
            assert sleeve_centre[1] == pytest.approx(porter_sleeve_height(sensor.arm_length, a), abs=TOL)


@pytest.mark.parametrize("sensor", SENSORS)
def test_governor_spindle_mark_goes_round_with_the_spindle(sensor):
    """The mark's horizontal position is r cos psi: it turns once per turn of the spindle."""
    a = sensor.stop_angles()[0]
    marks = np.array([sensor.outline(a, psi)["spindle_mark"][0] for psi in SPINDLE_ANGLES])
    radius = COLLAR_RADIUS * sensor.arm_length
    assert np.allclose(marks[:, 0], radius * np.cos(SPINDLE_ANGLES), atol=TOL)
    assert np.ptp(marks[:, 1]) > 0.0  # it goes round an ellipse, not along a line


@pytest.mark.parametrize("sensor", SENSORS)
def test_governor_sleeve_moves_between_its_stops_and_touches_them_at_the_ends(sensor):
    low_angle, high_angle = sensor.stop_angles()
    half_height = SLEEVE_HALF_HEIGHT * sensor.arm_length
    for a in stroke_angles(sensor):
        outline = sensor.outline(a, 0.0)
        (low_stop, high_stop) = outline["stops"][:, 0, 1]
        assert np.all(outline["stops"][:, 0, 1] == outline["stops"][:, 1, 1])  # the stops are horizontal
        assert outline["sleeve"][:, 1].min() >= low_stop - TOL
        assert outline["sleeve"][:, 1].max() <= high_stop + TOL
    bottom_at_low = sensor.outline(low_angle, 0.0)["sleeve"][:, 1].min()
    top_at_high = sensor.outline(high_angle, 0.0)["sleeve"][:, 1].max()
    assert bottom_at_low == pytest.approx(low_stop, abs=TOL)
    assert top_at_high == pytest.approx(high_stop, abs=TOL)
    assert high_stop - low_stop == pytest.approx(sensor.stroke[1] - sensor.stroke[0] + 2 * half_height, abs=TOL)


def test_ball_radius_is_a_steel_sphere_of_the_ball_mass():
    for mass in (0.5, 1.0, 4.0):
        r = porter(ball_mass=mass).ball_radius()
        assert 4.0 / 3.0 * math.pi * r**3 * 7850.0 == pytest.approx(mass, rel=1e-12)


@pytest.mark.parametrize("sensor", SENSORS)
def test_governor_bounds_contain_every_outline_over_the_stroke(sensor):
    bounds = sensor.bounds()
    radius = sensor.ball_radius()
    for a in stroke_angles(sensor, 53):
        for psi in SPINDLE_ANGLES:
            outline = sensor.outline(a, psi)
            for name, part in outline.items():
                assert inside(part, bounds, radius if name == "balls" else 0.0), (name, a, psi)
    # the widest ball at the high stop sets the width: no more than the margin beyond it
    xmax = bounds[1]
    widest = sensor.arm_length * math.sin(sensor.stop_angles()[1]) + radius
    span = max(bounds[1] - bounds[0], bounds[3] - bounds[2])
    assert widest < xmax <= widest + BOUNDS_MARGIN * span


def test_a_linkage_drawn_in_turn_with_another_keeps_its_own_outline():
    """mechanism_outline keeps one linkage's outliner (the spec drawn last): two linkages drawn in turn, each at the
    same angles, give each time the outline of a fresh outliner of its own spec, and their joints where the pose
    solver puts them (the geared shaker's crank pin on its crank circle: |pin - pivot| = the crank's length)."""
    from mech_regulator.mechanisms import mechanism_geometry
    from mech_regulator.mechanisms.linkage.drawing import linkage_outliner
    from mech_regulator.scene import load_scene

    specs = [load_scene(name).machine.mechanism for name in ("geared_shaker", "six_bar_press")]
    fresh = [linkage_outliner(*mechanism_geometry(spec)) for spec in specs]
    for phi in (0.0, 1.1, 4.0):
        for spec, outline_at in zip(specs * 2, fresh * 2):
            drawn, expected = mechanism_outline(spec, phi), outline_at(phi)
            assert drawn.keys() == expected.keys()
            assert all(np.array_equal(drawn[part], expected[part]) for part in drawn)
        pivot, pin = mechanism_outline(specs[0], phi)["crank"]
        linkage = mechanism_geometry(specs[0])[0]
        crank = linkage.link(linkage.driving_crank()).points
        length = max(abs(point - crank[linkage.crank_pivot().name]) for point in crank.values())  # [m]
        assert math.isclose(math.dist(pivot, pin), length, rel_tol=1e-12)
