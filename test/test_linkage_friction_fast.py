"""Joint friction on a general linkage (docs/theory.md §6) on both paths, its kinetostatics by groups written once, flat
(mechanisms/linkage/flat.py: kinetostatics, joint_loads), and generated per kind of linkage as straight-line code
(mechanisms/linkage/symbolic.py, joint_loads_source; test_linkage_symbolic_kinetostatics.py holds it to flat's), run as
plain Python by the reference path and compiled into the fast path's right-hand side.

The flat reactions were compared with the object implementation they replaced before it was deleted (the bundled
linkages, 50 random states each: the reactions to 7e-16 of the largest, the ratios exactly); what stays is
independent: the balancing moment from the reactions equals the reduced moment, a four-bar written as a linkage has
the preset's reactions (test_linkage.py, test_joint_friction.py), and the fast path equals the reference path."""

from __future__ import annotations

import math
import sys

import numpy as np
import pytest
from support import model_of, scene, simulate_complete
from test_compiled_path import assert_same_events, bundled, relative_difference

from mech_regulator.analysis.energy import energy_balance
from mech_regulator.mechanisms import build_kinetostatics, mechanism_geometry
from mech_regulator.mechanisms.linkage import flat, flat_kinetostatics, flat_poses, flat_program
from mech_regulator.scene import load_scene
from mech_regulator.solvers.compiled import fast_path_refusal
from mech_regulator.solvers.compiled.codegen import compile_scene

LINKAGES = ["shaper", "sieve_shaker", "six_bar_press", "walking_beam_linkage"]
GRAVITY = (1.5, -9.81)  # with a component along x, so that the weights' terms of both axes count


@pytest.mark.parametrize("name", LINKAGES)
def test_balancing_moment_equals_the_reduced_moment_at_many_angles(name):
    """From the reactions (mechanisms.build_kinetostatics: the generated joint loads) at 97 crank angles and
    random (omega, epsilon, Q): M_b0 + M_b1 epsilon = J epsilon + 1/2 J' omega^2 - M_weight - Q q' (J, J', M_weight,
    q' of flat_poses.reduced, the crank's own inertia included) to 1e-9 of the terms' size: a check of every reaction
    the crank's equilibrium sums, group by group inward."""
    mechanism = load_scene(name).machine.mechanism
    loads, _ = build_kinetostatics(mechanism, GRAVITY)
    core, structure = mechanism_geometry(mechanism)
    program = flat_program.encode(core, structure.groups, GRAVITY)
    rng = np.random.default_rng(21)
    for phi in np.linspace(0.0, 2.0 * math.pi, 98)[:-1] + 0.013:
        omega, epsilon, force = rng.uniform(-15.0, 15.0), rng.uniform(-60.0, 60.0), rng.uniform(-2000.0, 2000.0)
        J, dJ, weight, _, dq = flat_poses.reduced(phi, program, 0)
        expected = J * epsilon + 0.5 * dJ * omega**2 - weight - force * dq
        scale = abs(J * epsilon) + abs(0.5 * dJ * omega**2) + abs(weight) + abs(force * dq)
        balancing, rate = loads(phi, omega, force).balancing
        assert balancing + rate * epsilon == pytest.approx(expected, abs=1e-9 * scale)


def test_compiled_joint_loads_equal_plain_python():
    """One implementation: flat_kinetostatics.joint_loads run as plain Python (numba not involved) gives the compiled
    numbers to 1e-13 of the largest reaction, on the six-bar press (RRR, RRP) and the shaper (RPR, RRP)."""
    compiled = flat.compiled("joint_loads")
    for name in ("six_bar_press", "shaper"):
        core, structure = mechanism_geometry(load_scene(name).machine.mechanism)
        program = flat_program.encode(core, structure.groups, GRAVITY)
        for phi, omega, force in ((0.3, 10.0, 400.0), (2.9, -6.0, -150.0), (5.1, 0.0, 0.0)):
            plain, fast = (
                flat_kinetostatics.joint_loads(phi, omega, force, program, 0),
                compiled(phi, omega, force, program, 0),
            )
            scale = max(np.max(np.abs(plain[0])), np.max(np.abs(plain[1])))
            for ours, theirs in zip(plain[:3], fast[:3]):
                assert np.max(np.abs(ours - theirs)) <= 1e-13 * scale
            assert fast[3:] == pytest.approx(plain[3:], rel=1e-12)


def press(**changes) -> dict:
    """The bundled six_bar_press_friction as data, with scene() changes."""
    return scene(bundled("six_bar_press_friction"), **changes)


def test_compiled_right_hand_side_and_reactions_equal_the_model():
    """The fast path's right-hand side of the press with joint friction (six journals and the ram's guide) equals
    model.rhs at random states (1e-12), also with the friction continued along a piece (rate signs and the guide's
    normal sign held), and its `reactions` (the journals' |R|^2 the integrators keep their steps' reach from)
    equal MachineModel.joint_reactions squared."""
    model = model_of(press())
    friction = model.joint_friction
    assert friction.guides and len(friction.names) == 7
    compiled = compile_scene(model)
    reactions = sys.modules[f"mech_regulator_compiled_{compiled.path.stem.removeprefix('scene_')}"].reactions
    rng = np.random.default_rng(5)
    window = (0.2, 0.6)  # the rate signs held at its middle, the tables read on its middle's segment
    for k in range(12):
        y = np.array([rng.uniform(0.2, 0.6), rng.uniform(2.0, 14.0)])
        held = k % 2 == 1
        p = compiled.parameters_for(None, None, window if held else None, y[1])
        normal_signs = ()
        if held:
            normal_signs = compiled.hold_normal(p, 0.0, y, (), None)
        rates, squares = np.zeros(2), np.zeros(compiled.n_journals)
        compiled.rhs(0.0, y, p, rates)
        expected = model.rhs(None, window if held else None, normal_signs=normal_signs)(0.0, y)
        assert rates[1] == pytest.approx(expected[1], rel=1e-12, abs=1e-12 * abs(expected[1]) + 1e-13)
        reactions(0.0, y, p, squares)
        journals = model.joint_reactions(None, window if held else None, normal_signs=normal_signs)(0.0, y)
        assert compiled.n_journals == 6
        assert squares == pytest.approx(np.array(journals[:6]) ** 2, rel=1e-11)


def test_press_with_joint_friction_runs_the_same_on_both_paths():
    """The bundled six_bar_press_friction (one turn through a pressing stroke) on the fast path: the same events,
    switches and restarts as on the reference path, and its states within 10 times the fast run's own distance to
    one at 1/100 of the tolerances (as test_compiled_path's compressor_friction); the friction's work is negative
    and part of the energy balance."""
    data = press()
    assert fast_path_refusal(model_of(data)) is None
    reference = simulate_complete(model_of(data))
    fast = simulate_complete(model_of(scene(data, solver__path="fast")))
    settings = model_of(data).scene.solver
    tight = simulate_complete(
        model_of(scene(data, solver__path="fast", solver__rtol=settings.rtol / 100, solver__atol=settings.atol / 100))
    )
    assert_same_events(reference, fast)
    assert fast.stats.switches == reference.stats.switches > 0 and fast.stats.restarts == reference.stats.restarts
    assert np.all(relative_difference(reference, fast) <= 10.0 * relative_difference(tight, fast) + 1e-12)
    frictionless = simulate_complete(model_of(scene(data, machine__joint_friction=None)))
    assert fast(fast.t_end)[1] < frictionless(frictionless.t_end)[1]  # friction takes energy
    for run in (reference, fast):  # 3.7e-5 (0.225 J, at any rtol) while the corner of |k_C| at 0 was missed
        balance = energy_balance(model_of(data), run)
        assert balance.works["joint_friction"] < 0.0 and abs(balance.relative_residual) < 1e-8


def test_shaper_with_guide_friction_in_both_prismatic_joints_runs_the_same_on_both_paths():
    """The bundled shaper without gravity (so that the ram's guide G's N changes sign too) with f = 0.05 in every
    joint, its slot S and the ram's guide G both sliding with friction, over 1.2 s (more than a turn): each slider's N
    changes sign in the run, and the fast path (one held sign and one N guard per prismatic joint) has the same events,
    switches and restarts as the reference path, the switches the crank angles of the grid that phi passes plus every
    sign change of both N (counted on 4000 samples of the tight run), and its states within 10 times the fast run's
    own distance to one at 1/100 of the tolerances."""
    journals = "{" + ", ".join(f"{joint}: {{radius: 0.03, fit: run_in}}" for joint in ("O2", "A", "O4", "B", "C")) + "}"
    data = load_scene(
        "shaper",
        [
            "scenario.duration=1.2",
            "machine.gravity=[0.0, 0.0]",
            "machine.joint_friction.coefficient=0.05",
            "machine.joint_friction.guide=0.05",
            f"machine.joint_friction.journals={journals}",
        ],
    ).model_dump(exclude_none=True)
    model = model_of(data)
    assert [model.joint_friction.names[k] for k in model.joint_friction.guides] == ["S", "G"]
    assert fast_path_refusal(model) is None
    reference = simulate_complete(model)
    fast = simulate_complete(model_of(scene(data, solver__path="fast")))
    settings = model.scene.solver
    tight = simulate_complete(
        model_of(scene(data, solver__path="fast", solver__rtol=settings.rtol / 100, solver__atol=settings.atol / 100))
    )
    assert_same_events(reference, fast)
    assert fast.stats.restarts == reference.stats.restarts
    times = np.linspace(0.0, 1.2, 4001)
    states = tight(times)
    crossings = []
    for guide in range(2):
        normal = model.guide_normal(guide=guide)
        signs = np.sign([normal(t, states[:, k]) for k, t in enumerate(times)])
        crossings.append(int(np.count_nonzero(signs[1:] != signs[:-1])))
    assert min(crossings) >= 1
    grid, period = model.switch_grid(), model.dynamic_period()
    passed = sum(
        math.floor((states[0, -1] - angle) / period) - math.floor((states[0, 0] - angle) / period) for angle in grid
    )
    assert fast.stats.switches == tight.stats.switches == passed + sum(crossings)
    assert np.all(relative_difference(reference, fast) <= 10.0 * relative_difference(tight, fast) + 1e-12)


def test_held_rate_signs_are_those_of_the_rates_everywhere():
    """Between two corners the rhs reads rho_j s_j k_j for rho_j |k_j| (JointFrictionModel.ratio_signs): at 2000
    crank angles s_j k_j >= 0 for every joint with friction of the press. Its coupler-lever joint C has
    k_C = theta_coupler' - theta_lever' = 0 exactly at phi = 0 and 180 deg (the linkage is symmetric about the frame
    line there); its k(0) and k(2 pi) fell on both sides of 0 by round-off and the corner at 0 was missed, so k_C was
    read with the wrong sign from 0 to 24 deg."""
    friction = model_of(press()).joint_friction
    assert friction.corner_angles[0] == 0.0 and math.pi in friction.corner_angles
    for phi in np.linspace(0.0, 2.0 * math.pi, 2001)[:-1] + 1e-4:
        ratios = friction.loads(phi, 0.0, 0.0).ratios
        for index, sign in zip(friction.indices, friction.ratio_signs(phi)):
            assert sign * ratios[index] >= -1e-12, (math.degrees(phi), friction.names[friction.indices.index(index)])


def at_rest(torque: float) -> dict:
    """The press with joint friction at rest at phi = 1 rad (loads removed, gravity on), under a constant drive
    torque [N m]."""
    data = press(scenario__initial={"phi": 1.0, "omega": 0.0}, scenario__duration=0.3)
    data["machine"]["drive"] = {"type": "constant", "torque": torque}
    data["machine"]["loads"] = []
    return data


def test_a_crank_at_rest_under_friction_stays_at_rest_on_both_paths():
    """At rest the friction holds the crank while |M| <= F(0) (F(0): the friction of the reactions at rest, the
    links' weights carried by the journals and the guide): with the drive balancing the weight moment plus 0.9 F(0)
    the press stays exactly at rest on both paths (no event, omega 0 at every sample); with 1.1 F(0) it breaks away
    ('crank starts') at t = 0 on both paths, with epsilon > 0 and the same right-hand side."""
    model = model_of(at_rest(0.0))
    weight = model.reduced(1.0)[2]
    friction = model.joint_friction.joint_values(1.0, 0.0, 0.0, 0.0)[2]
    assert friction > 1.0  # the weights' reactions
    for share, moving in ((0.9, False), (1.1, True)):
        data = at_rest(-weight + share * friction)
        held = model_of(data)
        compiled = compile_scene(model_of(scene(data, solver__path="fast")))
        rates, y = np.zeros(2), np.array([1.0, 0.0])
        compiled.rhs(0.0, y, compiled.parameters_for(None, None, None), rates)
        expected = held.rhs()(0.0, y)[1]
        assert rates[1] == pytest.approx(expected, rel=1e-12, abs=0.0)
        assert (expected > 0.0) if moving else (expected == 0.0)
        reference = simulate_complete(held)
        fast = simulate_complete(model_of(scene(data, solver__path="fast")))
        assert_same_events(reference, fast)
        if moving:
            assert [name for _, name in fast.events] == ["crank starts"] and fast(0.3)[1] > 0.0
        else:
            assert fast.events == reference.events == []
            assert np.all(fast(np.linspace(0.0, 0.3, 7))[1] == 0.0)
            assert np.all(reference(np.linspace(0.0, 0.3, 7))[1] == 0.0)
