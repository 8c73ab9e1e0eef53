"""The linkage solver written once (mechanisms/linkage/flat.py): the reference path and the compiled fast
path run the same functions, so a linkage scene gives the same omega trace on both; the flat reduced quantities
against independent checks (their derivatives against central differences, plain Python against compiled)."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from support import model_of, simulate_complete
from test_compiled_path import assert_same_rhs, driven_four_bar
from test_linkage import DYADS, four_bar_linkage
from test_linkage_scene import FOUR_BAR_LINKAGE

from mech_regulator import mechanisms
from mech_regulator.mechanisms.linkage import (
    LinkageError,
    analyse,
    flat_derivatives,
    flat_poses,
    flat_program,
    make_reduced,
    solve,
)
from mech_regulator.model import build_model
from mech_regulator.scene import load_scene
from mech_regulator.solvers import on_path
from mech_regulator.solvers.compiled import fast_path_refusal
from mech_regulator.solvers.compiled.codegen import generate

LINKAGE_SCENES = ["shaper", "sieve_shaker", "six_bar_press", "walking_beam_linkage"]
ANGLES = np.linspace(0.1, 2.0 * math.pi, 7)


def _program(name: str) -> tuple[np.ndarray, object]:
    """The flat program of a bundled scene's linkage (with its gravity) and its reference reduced(phi)."""
    machine = load_scene(name).machine
    core, structure = mechanisms.mechanism_geometry(machine.mechanism)
    return flat_program.encode(core, structure.groups, machine.gravity), make_reduced(core, structure, machine.gravity)


@pytest.mark.parametrize("name", LINKAGE_SCENES)
def test_reference_and_fast_paths_give_the_same_omega_trace(name):
    """A bundled linkage scene over 0.3 s: the fast path's omega trace equals the reference path's to 1e-12
    (relative to the largest |omega|); both run flat_poses.reduced, compiled once."""
    model = build_model(load_scene(name, ["scenario.duration=0.3"]))
    reference, fast = (simulate_complete(on_path(model, path)) for path in ("reference", "fast"))
    times = np.linspace(0.0, 0.3, 61)
    omega_reference = np.array([reference(t)[1] for t in times])
    omega_fast = np.array([fast(t)[1] for t in times])
    scale = np.max(np.abs(omega_reference))
    assert scale > 0.0
    np.testing.assert_allclose(omega_fast, omega_reference, rtol=0.0, atol=1e-12 * scale)


@pytest.mark.parametrize("name", LINKAGE_SCENES)
def test_compiled_rhs_equals_the_reference_rhs_of_a_linkage_scene(name):
    """The generated right-hand side of a linkage scene against the model's at random states (J, dJ/dphi and the
    weight moment of the linkage; slider_viscous read through dq of its output joint)."""
    model = on_path(build_model(load_scene(name)), "fast")
    assert_same_rhs(model, [None])


def test_a_linkage_as_the_driven_part_behind_a_coupling_compiles_to_the_reference_rhs():
    """two_mass with the four-bar written as a linkage on its driven part (weighing links, rocker loads read through
    the output link's angle, a table on phi_driven): the compiled right-hand side equals the model's in every driven
    mode."""
    data = driven_four_bar()
    data["machine"]["coupling"]["driven"]["mechanism"] = FOUR_BAR_LINKAGE
    model = model_of(data)
    assert fast_path_refusal(model) is None
    assert re.search(r"= linkage_reduced_\w+\(phi2, p, ", generate(model)[0])
    assert_same_rhs(model, [("forward",), ("backward",), ("held",)], states=5)


@pytest.mark.parametrize("name", LINKAGE_SCENES)
def test_flat_reduced_plain_python_equals_compiled_and_its_derivatives_are_central_differences(name):
    """flat_poses.reduced run as plain Python equals the compiled one to 1e-13; its dJ/dphi and dq/dphi equal central
    differences of J and q (step 1e-5 rad: truncation ~1e-10 relative, bound 1e-6)."""
    program, reduced = _program(name)
    step = 1e-5
    for phi in ANGLES:
        plain = flat_poses.reduced(phi, program, 0)
        compiled = reduced(phi)
        np.testing.assert_allclose(plain, compiled, rtol=1e-13, atol=1e-13 * max(map(abs, compiled)))
        J, dJ, weight, q, dq = compiled
        above, below = reduced(phi + step), reduced(phi - step)
        assert dJ == pytest.approx((above[0] - below[0]) / (2 * step), rel=1e-6, abs=1e-8 * J)
        assert dq == pytest.approx((above[3] - below[3]) / (2 * step), rel=1e-6, abs=1e-9)


def test_weight_moment_is_minus_the_rate_of_potential_energy():
    """The six-bar press's M_weight against -dV/dphi by central differences, V = -sum m_k g . S_k over its links'
    centres from kinematics.solve (the dict form)."""
    machine = load_scene("six_bar_press").machine
    core, structure = mechanisms.mechanism_geometry(machine.mechanism)
    reduced = make_reduced(core, structure, machine.gravity)
    g = complex(*machine.gravity)

    def potential(phi: float) -> float:
        poses = solve(core, structure, phi, derivatives=False)
        return -sum(
            link.mass
            * (
                g.conjugate()
                * (
                    poses[link.name][0]
                    + link.centre * complex(math.cos(poses[link.name][1]), math.sin(poses[link.name][1]))
                )
            ).real
            for link in core.links
            if link.name != core.frame
        )

    step = 1e-5
    for phi in ANGLES:
        expected = -(potential(phi + step) - potential(phi - step)) / (2 * step)
        assert reduced(phi)[2] == pytest.approx(expected, rel=1e-6, abs=1e-6)


def test_a_group_that_cannot_assemble_gives_the_same_clear_message_from_reduced_and_solve():
    """A four-bar whose rocker cannot reach over part of the turn: reduced(phi) (compiled, NaN there) raises the
    LinkageError of the dict solve, naming the RRR group, its links, the angle and the distances."""
    linkage = four_bar_linkage(c=0.8)  # crank 1, coupler 3, frame 3.5: |D - B| up to 4.5 > 3 + 0.8
    structure = analyse(linkage)
    reduced = make_reduced(linkage, structure, None)
    with pytest.raises(LinkageError) as from_solve:
        solve(linkage, structure, math.pi)
    with pytest.raises(LinkageError) as from_reduced:
        reduced(math.pi)
    assert str(from_reduced.value) == str(from_solve.value)
    assert str(from_solve.value).startswith(
        "RRR group rocker_pin (links coupler, rocker) at crank angle 180.000 deg cannot be assembled: the distance "
    )


def test_a_slider_table_on_a_linkage_output_runs_the_same_on_both_paths():
    """The sieve shaker with a slider force table (five points over its output's travel, so x(phi) crosses three
    interior breakpoints a turn: kinks the solvers restart on) and a slider spring: both read q, q' of the linkage's
    output joint; the fast path's omega trace equals the reference path's to 1e-12 of its largest |omega|, and the
    compiled right-hand side the model's inside a window between two kinks."""
    machine = load_scene("sieve_shaker").machine
    core, structure = mechanisms.mechanism_geometry(machine.mechanism)
    travel = [make_reduced(core, structure, None)(phi)[3] for phi in np.linspace(0.0, 2.0 * math.pi, 721)]
    positions = np.linspace(min(travel), max(travel), 5).tolist()
    table = {"type": "slider_table", "position": positions, "force": [0.0, -40.0, -10.0, -60.0, 0.0]}
    spring = {"type": "slider_spring", "stiffness": 500.0, "free_position": positions[2]}
    data = load_scene("sieve_shaker", ["scenario.duration=0.3"]).model_dump(exclude_none=True)
    data["machine"]["loads"] += [table, spring]
    model = model_of(data)
    kinks = sorted(angle for effect in model.effects for angle in effect.kink_angles)
    assert len(kinks) >= 3
    reference, fast = (simulate_complete(on_path(model, path)) for path in ("reference", "fast"))
    assert reference.stats.restarts > 0
    times = np.linspace(0.0, 0.3, 61)
    omega_reference = np.array([reference(t)[1] for t in times])
    omega_fast = np.array([fast(t)[1] for t in times])
    np.testing.assert_allclose(omega_fast, omega_reference, rtol=0.0, atol=1e-12 * np.max(np.abs(omega_reference)))
    assert_same_rhs(model, [None], window=(kinks[0] + 1e-3, kinks[1] - 1e-3))


@pytest.mark.parametrize("kind", sorted(DYADS))
def test_a_dyads_inverse_by_elimination_is_numpys_inverse(kind):
    """flat_derivatives.invert_dyad (the external joints' 2 x 3 rows, then a 2 x 2 system for the internal joint)
    against np.linalg.inv of the same group matrix, plain Python, at six crank angles: equal to 1e-12 of the largest
    entry and A A^-1 = I."""
    linkage = DYADS[kind]()
    structure = analyse(linkage)
    program = flat_program.encode(linkage, structure.groups, None)
    g = flat_program.HEADER_SIZE + flat_program.LINK_SIZE * int(program[0])
    poses, scratch = np.empty(flat_program.POSE_SIZE * int(program[0])), np.empty(flat_program.SCRATCH_SHAPE)
    for phi in np.linspace(0.3, 2.0 * math.pi, 6):
        assert flat_poses.solve_poses(phi, program, 0, poses, scratch, False)[0] == flat_program.SOLVED
        A, inverse, known = np.empty((6, 6)), np.empty((6, 6)), np.empty((2, 6))
        flat_derivatives.group_matrix(program, g, poses, A, known)
        assert flat_derivatives.invert_dyad(A, inverse)
        expected = np.linalg.inv(A)
        np.testing.assert_allclose(inverse, expected, rtol=0.0, atol=1e-12 * np.abs(expected).max())
        np.testing.assert_allclose(A @ inverse, np.eye(6), rtol=0.0, atol=1e-12)


def test_a_group_at_a_dead_point_is_named_with_its_angle():
    """A change-point four-bar (crank 1, coupler 3, rocker 1, frame 3): at phi = 180 deg its coupler and rocker lie
    stretched along one line (|B - D| = b + c), at 0 deg folded (|B - D| = b - c), where A is singular: solve and
    reduced name the group's dead point, plain Python flat_poses.solve_poses gives the same status; a degree away the
    group solves."""
    linkage = four_bar_linkage(a=1.0, b=3.0, c=1.0, d=3.0, th1=0.0)
    structure = analyse(linkage)
    reduced = make_reduced(linkage, structure, None)
    program = flat_program.encode(linkage, structure.groups, None)
    for phi, degrees in ((math.pi, "180.000"), (0.0, "0.000")):
        expected = (
            f"RRR group rocker_pin (links coupler, rocker) is at a dead point at crank angle {degrees} deg: its "
            "links are aligned and its velocity ratios infinite"
        )
        with pytest.raises(LinkageError) as from_solve:
            solve(linkage, structure, phi)
        with pytest.raises(LinkageError) as from_reduced:
            reduced(phi)
        assert str(from_solve.value) == str(from_reduced.value) == expected
        plain = flat_poses.solve_poses(
            phi, program, 0, np.empty(flat_program.POSE_SIZE * 4), np.empty(flat_program.SCRATCH_SHAPE), True
        )
        assert plain[:2] == (flat_program.DEAD_POINT, 0)
        assert all(math.isfinite(value) for value in reduced(phi + math.radians(1.0)))
