"""The corners of a linkage's joint friction located on the reference path.

A linkage's friction F = M_collar + sum_j rho_j |k_j| |R_j| + sum_g f_guide |v_g| |N_g| has a kink where a joint's
relative rate changes sign (fixed crank angles, `JointFrictionModel.corner_angles`) and where the normal force N_g of
a prismatic joint changes sign (a guard on the state per prismatic joint). Both are located on the reference path, as
the crank-slider's (test_friction_corners.py); between two of them the rhs reads F continued along its piece. Where
the reactions of several journals pass close to zero together (the six-bar press), the steps stay away from the
branch points of their |R| in complex time (time_domain._reaction_branches)."""

from __future__ import annotations

import math

import numpy as np
from support import simulate_complete

from mech_regulator.mechanisms import mechanism_geometry
from mech_regulator.mechanisms.linkage.kinetostatics import make_kinetostatics
from mech_regulator.model import build_model
from mech_regulator.scene import load_scene

FRICTION = [
    "machine.joint_friction.coefficient=0.05",
    "machine.joint_friction.guide=0.05",
    "machine.joint_friction.journals={"
    + ", ".join(f"{joint}: {{radius: 0.03, fit: run_in}}" for joint in ("O2", "A", "O4", "B", "C"))
    + "}",
]


def six_bar_press(duration: float, *settings: str):
    """The bundled six-bar press with f = 0.05 in every joint (journals A-F 30 mm run in, the ram's guide G) over
    duration [s], with --set style settings."""
    journals = "{" + ", ".join(f"{joint}: {{radius: 0.03, fit: run_in}}" for joint in "ABCDEF") + "}"
    return build_model(
        load_scene(
            "six_bar_press",
            [f"scenario.duration={duration}", *FRICTION[:2], f"machine.joint_friction.journals={journals}", *settings],
        )
    )


def shaper(duration: float, *settings: str):
    """The bundled shaper (a six-bar with two prismatic joints: the block in the lever's slot S, the ram's guide G)
    with friction in every joint, over duration [s], with --set style settings."""
    return build_model(load_scene("shaper", [f"scenario.duration={duration}", *FRICTION, *settings]))


def test_a_prismatic_joints_reaction_is_its_normal_force_in_the_guides_frame():
    """Joint friction reads a prismatic joint's reaction as i N (Im R = N, |R| = |N|, as a crank-slider's guide):
    R0 + R1 epsilon equals i N of the linkage's kinetostatics at (phi, omega, epsilon, Q), for both sliders."""
    model = shaper(0.1)
    friction = model.joint_friction
    assert [friction.names[k] for k in friction.guides] == ["S", "G"]
    loads = make_kinetostatics(*mechanism_geometry(model.scene.machine.mechanism), (0.0, -9.81))
    for phi, omega, epsilon, force in ((0.4, 6.0, 3.0, -800.0), (3.9, 7.5, -20.0, 250.0)):
        parts = friction.loads(phi, omega, force)
        for k in friction.guides:
            index = friction.indices[k]
            reaction = parts.constant[index] + parts.per_epsilon[index] * epsilon
            normal = loads(phi, omega, epsilon, force).reactions[friction.names[k]][0]
            assert abs(reaction - 1j * normal) <= 1e-9 * (1.0 + abs(normal))


def test_shaper_with_joint_friction_meets_its_rtol():
    """The shaper with friction (DOP853, reference path), omega over 1 s at rtol 1e-11 against rtol 1e-13: within
    3 rtol of its largest value (measured 0.40; 438 rtol before the prismatic joints' N = 0 were located, 2.1 before
    steps were kept away from the branch points of the journals' |R|). The run locates every
    corner: switches = the crank angles of the grid that phi passes plus the sign changes of both sliders' N,
    counted on 2000 samples of the tight run."""
    tight = simulate_complete(shaper(1.0, "solver.rtol=1e-13", "solver.atol=1e-15"))
    run = simulate_complete(shaper(1.0, "solver.rtol=1e-11", "solver.atol=1e-13"))
    times = np.linspace(0.0, 1.0, 2001)
    states = tight(times)
    assert np.max(np.abs(run(times)[1] - states[1])) <= 3.0 * 1e-11 * np.max(np.abs(states[1]))
    model = shaper(1.0)
    crossings = 0
    for guide in range(len(model.joint_friction.guides)):
        normal = model.guide_normal(guide=guide)
        signs = np.sign([normal(t, states[:, k]) for k, t in enumerate(times)])
        crossings += int(np.count_nonzero(signs[1:] != signs[:-1]))
    grid, period = model.switch_grid(), model.dynamic_period()
    passed = sum(
        math.floor((states[0, -1] - angle) / period) - math.floor((states[0, 0] - angle) / period) for angle in grid
    )
    assert crossings >= 1
    assert run.stats.switches == tight.stats.switches == passed + crossings


def test_six_bar_press_meets_its_rtol_as_its_reactions_pass_near_zero():
    """The six-bar press with friction (DOP853, reference path), omega over 0.5 s at rtol 1e-9 against rtol 1e-13:
    within 3 rtol of its largest value (measured 0.59; 58 before steps were kept away from the branch points of the
    journals' |R|: near 176 deg, as the ram's N passes 0, the load reverses through the chain and the reactions of
    F, E and B fall to 10, 29 and 42 N of up to 560 N; one DOP853 step across them carried the whole error)."""
    tight = simulate_complete(six_bar_press(0.5, "solver.rtol=1e-13", "solver.atol=1e-15"))
    run = simulate_complete(six_bar_press(0.5, "solver.rtol=1e-9", "solver.atol=1e-11"))
    times = np.linspace(0.0, 0.5, 2001)
    omega = tight(times)[1]
    assert np.max(np.abs(run(times)[1] - omega)) <= 3.0 * 1e-9 * np.max(np.abs(omega))
