"""The corners of joint friction (docs/theory.md §6.5) located on both paths.

F = M_collar + sum_j rho_j |k_j| |R_j| + f_guide |x'| |N| has a kink where a joint's relative rate k_j changes sign
(fixed crank angles: the guide's x' at the dead centres, the wrist pin's theta' where the rod turns back) and where
the guide's normal force N changes sign (a guard on the state). Both are located; between two of them the solvers
read F continued along its piece, so compressor_friction meets its rtol as a smooth scene does (docs/hard_cases.md,
"Joint friction's output force"). A journal's |R| that passes close to 0 without a sign change has branch points in
complex time near its minimum; the adaptive one-step methods keep every step at least its own length away from them
(time_domain._reaction_branches)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from support import simulate_complete

from mech_regulator.model import build_model
from mech_regulator.scene import load_scene
from mech_regulator.solvers.time_domain import _reach, _reaction_branches, switch_window

CRANK, ROD = 0.05, 0.20  # compressor.yaml's crank-slider [m]


def compressor(duration: float, *settings: str):
    """The bundled compressor_friction over duration [s] with --set style settings."""
    return build_model(load_scene("compressor_friction", [f"scenario.duration={duration}", *settings]))


def test_corner_angles_are_where_the_relative_rates_change_sign():
    """The guide's x' vanishes at the dead centres, where crank and rod align with the slider's line y = e:
    sin phi = e / (l + R) (outer) and sin(phi - pi) = e / (l - R) (inner); the wrist pin's rate theta' (the rod's,
    sin theta = (e - R sin phi) / l) where cos phi = 0. Without offset 0, 90, 180, 270 deg."""
    for offset in (0.0, 0.01):
        friction = compressor(0.1, f"machine.mechanism.offset={offset}").joint_friction
        outer = math.asin(offset / (ROD + CRANK))
        inner = math.pi + math.asin(offset / (ROD - CRANK))
        expected = sorted([outer % (2.0 * math.pi), 0.5 * math.pi, inner, 1.5 * math.pi])
        assert np.allclose(friction.corner_angles, expected, rtol=0.0, atol=1e-12)
        assert [friction.names[k] for k in friction.guides] == ["guide"]


def test_the_rhs_between_corners_is_the_friction_continued():
    """Inside each window between corners, with the sign of N at the state, the rhs the solvers integrate equals the
    friction itself (epsilon to 1e-12); 0.1 rad beyond the window's end, where the wrist pin's rate or x' has
    changed sign (N read with its own sign there), it is the friction continued (s_j k_j < 0) and differs from it."""
    model = compressor(0.3)
    grid, period = np.array(model.switch_grid()), model.dynamic_period()
    true_rhs = model.rhs()
    before_corners = []  # whether the rhs continued 0.1 rad beyond a window that ends on a corner differs
    for phi in np.linspace(0.01, 2.0 * math.pi - 0.01, 60):
        y = np.array([phi, 40.0])
        window = switch_window(grid, period, phi, forward=True)
        side = 1.0 if model.guide_normal(None, window)(0.0, y) >= 0.0 else -1.0
        epsilon = model.rhs(None, window, normal_signs=(side,))(0.0, y)[1]
        assert abs(epsilon - true_rhs(0.0, y)[1]) <= 1e-12 * abs(true_rhs(0.0, y)[1])
        beyond = np.array([window[1] + 0.1, 40.0])
        if any(abs(window[1] - corner) < 1e-9 for corner in (0.5 * math.pi, math.pi, 1.5 * math.pi, 2.0 * math.pi)):
            side = 1.0 if model.guide_normal()(0.0, beyond) >= 0.0 else -1.0  # N's own sign there: only k_j continued
            before_corners.append(
                model.rhs(None, window, normal_signs=(side,))(0.0, beyond)[1] != true_rhs(0.0, beyond)[1]
            )
    assert len(before_corners) >= 20 and all(before_corners)


def test_compressor_friction_meets_its_rtol_on_both_paths():
    """compressor_friction (DOP853, started from rest), omega over 0.3 s at rtol 1e-11 against rtol 1e-13: within
    5 rtol of its largest value on both paths (before the corners were located 5900 rtol). Each path locates every
    corner: switches = the crank angles of the grid (corners and the slider table's knots) that phi passes plus the
    sign changes of N, counted on 3000 samples of the tight run."""
    tight = simulate_complete(compressor(0.3, "solver.rtol=1e-13", "solver.atol=1e-15"))
    times = np.linspace(0.0, 0.3, 3001)
    omega = tight(times)[1]
    runs = [
        simulate_complete(compressor(0.3, "solver.rtol=1e-11", "solver.atol=1e-13", f"solver.path={path}"))
        for path in ("reference", "fast")
    ]
    for run in runs:
        assert np.max(np.abs(run(times)[1] - omega)) <= 5.0 * 1e-11 * np.max(np.abs(omega))
    model = compressor(0.3)
    normal = model.guide_normal()
    states = tight(times)
    signs = np.sign([normal(t, states[:, k]) for k, t in enumerate(times)])
    phi_end = states[0, -1]
    grid, period = np.array(model.switch_grid()), model.dynamic_period()
    passed = sum(math.floor((phi_end - angle) / period) - math.floor((0.0 - angle) / period) for angle in grid)
    expected = passed + int(np.count_nonzero(signs[1:] != signs[:-1]))
    assert [run.stats.switches for run in runs] == [tight.stats.switches] * 2 == [expected] * 2


def test_branch_points_of_a_reaction_passing_near_zero_are_the_closed_form():
    """|R|^2 = |R_m|^2 + |R'|^2 (t - t_m)^2 vanishes at t_m +- i |R_m| / |R'|: found on a step (0.1, 0.12] s for a
    reaction of 1.4 N at its minimum at 0.113 s falling by 2e4 N/s (the compressor's wrist pin), to 3e-12 s (the
    degree-8 interpolant of the quadratic |R|^2 has its other zeros, from round-off, some 100 steps away). The
    reach is the longest step whose every point stays its own length away from them: (x^2 + rho^2) / (2 x) from
    0.1 s (x = 0.013 s ahead), rho from 0.113 s (beside), the distance to them from 0.2 s (behind)."""
    minimum, rate, at = 1.4j, -2.0e4, 0.113

    def reactions(t, y):  # a journal with R(t) = R_m + R' (t - t_m) [N] (complex, R_m perpendicular to R')
        return [abs(minimum + rate * (t - at))]

    branches = _reaction_branches(reactions, (0,), lambda times: np.zeros((2, np.size(times))), 0.1, 0.12)
    rho = abs(minimum) / abs(rate)
    near = np.sort_complex(branches[np.abs(branches - 0.11) < 1.0])  # the interpolant's other zeros: round-off, > 1 s
    assert near == pytest.approx(np.array([at - 1j * rho, at + 1j * rho]), abs=3e-12)
    x = at - 0.1
    assert _reach(branches, 0.1) == pytest.approx((x * x + rho * rho) / (2.0 * x), rel=1e-9)
    assert _reach(branches, at) == pytest.approx(rho, rel=1e-6)
    assert _reach(branches, 0.2) == pytest.approx(math.hypot(0.2 - at, rho), rel=1e-9)
    for branch in (3.0 + 1.0j, 0.5 + 2.0j, -1.0 + 0.5j):  # from the step's every point at least the step's length
        h = _reach(np.array([branch]), 0.0)
        nearest = min(abs(branch - s) for s in np.linspace(0.0, h, 100001))
        assert nearest == pytest.approx(h, rel=1e-6)


def test_compressor_friction_meets_its_rtol_where_a_reaction_passes_near_zero():
    """compressor_friction (DOP853), omega over 0.5 s at rtol 1e-9 against rtol 1e-13 (reference path): within 3 rtol
    of its largest value on both paths (measured 0.75 rtol on each, with the same 120 steps, which
    test_compiled_path.test_crank_stops_and_starts_as_on_the_reference_path compares; 26 before
    steps were kept away from the branch points of the journals' |R|: the crank bearing's and crank pin's reactions
    fall to 12 N of 40 N at 199 deg, the wrist pin's to 1.4 N of 145 N at 129.5 deg, and single DOP853 steps across
    them had 14-22 times their tolerance)."""
    tight = simulate_complete(compressor(0.5, "solver.rtol=1e-13", "solver.atol=1e-15"))
    runs = [
        simulate_complete(compressor(0.5, "solver.rtol=1e-9", "solver.atol=1e-11", f"solver.path={path}"))
        for path in ("reference", "fast")
    ]
    times = np.linspace(0.0, 0.5, 2001)
    omega = tight(times)[1]
    for run in runs:
        assert np.max(np.abs(run(times)[1] - omega)) <= 3.0 * 1e-9 * np.max(np.abs(omega))
