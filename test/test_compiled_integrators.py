"""The compiled steppers against scipy's own steppers (same steps up to round-off), the reference RK4, closed
forms and the reference path's event semantics; the Python wrappers CompiledRun and StepsDense."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit
from scipy.integrate import DOP853, RK45, OdeSolution
from scipy.linalg import expm

from mech_regulator.solvers.compiled import integrators as compiled
from mech_regulator.solvers.compiled.results import CompiledRun, StepsDense
from mech_regulator.solvers.compiled.signatures import GUARDS_SIGNATURE, REACTIONS_SIGNATURE, RHS_SIGNATURE
from mech_regulator.solvers.compiled.steppers import NO_RESTARTS, stepper
from mech_regulator.solvers.rk4 import RK4
from mech_regulator.solvers.time_domain import PROBES_PER_STEP
from mech_regulator.solvers.trajectory import Trajectory

STIFF = np.array([[1.0, 1.0], [1.0, -1.0]]) @ np.diag([-1.0, -1e6]) @ np.linalg.inv([[1.0, 1.0], [1.0, -1.0]])


@njit(RHS_SIGNATURE, cache=True)
def van_der_pol(t, y, p, dydt):
    """x'' - mu (1 - x^2) x' + x = 0 with mu = p[0]."""
    dydt[0] = y[1]
    dydt[1] = p[0] * (1.0 - y[0] * y[0]) * y[1] - y[0]


@njit(RHS_SIGNATURE, cache=True)
def oscillator(t, y, p, dydt):
    """x'' = -p[0] x (p[0] = omega^2 [1/s^2])."""
    dydt[0] = y[1]
    dydt[1] = -p[0] * y[0]


@njit(RHS_SIGNATURE, cache=True)
def constant_acceleration(t, y, p, dydt):
    """x'' = p[0]: x is a parabola in t, which every method and dense output here reproduces exactly."""
    dydt[0] = y[1]
    dydt[1] = p[0]


@njit(RHS_SIGNATURE, cache=True)
def stiff_linear(t, y, p, dydt):
    """y' = A y, A = p[:4] row by row (eigenvalues -1 and -1e6 for STIFF)."""
    dydt[0] = p[0] * y[0] + p[1] * y[1]
    dydt[1] = p[2] * y[0] + p[3] * y[1]


@njit(RHS_SIGNATURE, cache=True)
def rotating_pendulum(t, y, p, dydt):
    """phi'' = -p[0] sin phi + p[1] (1 - phi' / p[2]): a driven pendulum turning over, periodic in phi (2 pi)."""
    dydt[0] = y[1]
    dydt[1] = -p[0] * np.sin(y[0]) + p[1] * (1.0 - y[1] / p[2])


@njit(RHS_SIGNATURE, cache=True)
def blow_up(t, y, p, dydt):
    """y' = y^2: y = 1 / (1 - t) from y(0) = 1 escapes to infinity at t = 1."""
    dydt[0] = y[0] * y[0]


@njit(RHS_SIGNATURE, cache=True)
def reaction_size(t, y, p, dydt):
    """y' = |R(t)|, R = R_m + R' (t - t_m) with R_m = i p[0] perpendicular to R' = p[1], t_m = p[2] [s]."""
    dydt[0] = math.sqrt(p[0] * p[0] + (p[1] * (t - p[2])) ** 2)


@njit(REACTIONS_SIGNATURE, cache=True)
def reaction_square(t, y, p, squares):
    """|R(t)|^2 of reaction_size's journal."""
    squares[0] = p[0] * p[0] + (p[1] * (t - p[2])) ** 2


@njit(GUARDS_SIGNATURE, cache=True)
def position_and_clock(t, y, p, levels):
    """levels[0] = x - p[1] (linear in the state), levels[1] = p[2] - t (reads t: probed)."""
    levels[0] = y[0] - p[1]
    levels[1] = p[2] - t


@njit(GUARDS_SIGNATURE, cache=True)
def position(t, y, p, levels):
    """levels[0] = x - p[1]."""
    levels[0] = y[0] - p[1]


@njit(GUARDS_SIGNATURE, cache=True)
def exponential_position(t, y, p, levels):
    """levels[0] = exp(x) - 1: the sign of x, but not linear in it (probed)."""
    levels[0] = np.exp(y[0]) - 1.0


NO_LINES = np.zeros((0, 4))
POSITION_LINE = np.array([[1.0, 0.0, 1.0, 0.0]])  # flag, c0, c_x, c_v: the guard x - p[1] with c0 set per test
TWO_GUARD_LINES = np.array([[1.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 0.0]])


def adaptive(
    method,
    rhs,
    y0,
    t_end,
    p,
    rtol=1e-6,
    atol=1e-9,
    guards=position,
    lines=NO_LINES,
    thresholds=None,
    max_step=np.inf,
    first_step=0.0,
    wrap_limit=np.inf,
    wrap_period=0.0,
    max_steps=100000,
    reactions=position,
    n_journals=0,
    run_steps=100000,
    restarts=NO_RESTARTS,
):
    """The compiled run of the adaptive stepper of `method` (its name: the stepper is compiled or loaded when a test
    first runs it, not when the suite is collected, which every pytest-xdist worker does) from y0 at t = 0 to t_end."""
    y0 = np.asarray(y0, dtype=float)
    thresholds = np.zeros(len(lines)) if thresholds is None else np.asarray(thresholds, dtype=float)
    return CompiledRun.from_result(
        stepper(method)(
            rhs,
            guards,
            len(lines),
            np.ascontiguousarray(lines),
            thresholds,
            reactions,
            n_journals,
            0.0,
            y0,
            t_end,
            np.asarray(p, dtype=float),
            rtol,
            np.full(y0.size, atol),
            max_step,
            first_step,
            wrap_limit,
            wrap_period,
            max_steps,
            run_steps,
            *restarts,
        )
    )


def fixed(
    rhs,
    y0,
    t_end,
    p,
    step,
    guards=position,
    lines=NO_LINES,
    wrap_limit=np.inf,
    wrap_period=0.0,
    max_steps=100000,
    run_steps=100000,
    restarts=NO_RESTARTS,
):
    """The compiled run of the RK4 stepper at a fixed `step` from y0 at t = 0 to t_end."""
    y0 = np.asarray(y0, dtype=float)
    return CompiledRun.from_result(
        stepper("RK4")(
            rhs,
            guards,
            len(lines),
            np.ascontiguousarray(lines),
            np.zeros(len(lines)),
            0.0,
            y0,
            t_end,
            np.asarray(p, dtype=float),
            step,
            wrap_limit,
            wrap_period,
            max_steps,
            run_steps,
            *restarts,
        )
    )


def stepped(solver):
    """Step a scipy solver to its end: step times, states at each step start, dense outputs."""
    times, starts, dense = [solver.t], [], []
    while solver.status == "running":
        starts.append(solver.y.copy())
        solver.step()
        times.append(solver.t)
        dense.append(solver.dense_output())
    return np.array(times), np.array(starts), dense


def vdp_python(t, y):
    return np.array([y[1], (1.0 - y[0] ** 2) * y[1] - y[0]])


@pytest.mark.parametrize("method, scipy_method, same_solution", [("RK45", RK45, 5e-12), ("DOP853", DOP853, 1e-12)])
def test_the_same_steps_as_scipy(method, scipy_method, same_solution):
    """Van der Pol at mu = 1 over [0, 20]: scipy's solver stepped by hand takes the same steps and the same rhs
    calls (scipy's DOP853 spends its 3 dense-output calls when asked, here every step). The step edges agree to
    1e-7 relative, not to round-off: the error estimate is a sum of stages that cancel, the compiled stepper sums
    them in plain loops where scipy calls BLAS, and the controller carries that difference (measured 1.4e-8). The
    solution is the same: the compiled states at its own step edges and its dense output inside the steps lie on
    scipy's dense output to 5e-12 on |x| <= 2 (measured 1.4e-13 and 5e-13 after 176 RK45 steps; 4e-14 and
    7e-14 after 69 DOP853 steps), and the end states agree to 1e-12."""
    run = adaptive(method, van_der_pol, [2.0, 0.0], 20.0, [1.0], rtol=1e-6, atol=1e-9)
    solver = scipy_method(vdp_python, 0.0, np.array([2.0, 0.0]), 20.0, rtol=1e-6, atol=1e-9)
    times, _, dense = stepped(solver)
    assert run.status == compiled.REACHED and run.n_steps == len(dense) > 50
    assert run.nfev == solver.nfev
    np.testing.assert_allclose(run.times, times, rtol=1e-7, atol=0)
    scipy_solution = OdeSolution(times, dense)
    np.testing.assert_allclose(run.y_old, scipy_solution(run.times[:-1]).T, rtol=0, atol=same_solution)
    np.testing.assert_allclose(run.y_end, solver.y, rtol=0, atol=1e-12)
    inside = (run.times[:-1] + np.array([0.13, 0.5, 0.91])[:, None] * np.diff(run.times)).T.ravel()
    np.testing.assert_allclose(run.dense(inside), scipy_solution(inside), rtol=0, atol=same_solution)
    assert run.last_step == pytest.approx(solver.step_size, rel=1e-7)


def test_dop853_dense_output_in_powers_of_theta_is_scipys():
    """One DOP853 step of 0.8 s on Van der Pol: the 7th-degree power form equals scipy's nested
    Dop853DenseOutput inside the step to round-off."""
    run = adaptive("DOP853", van_der_pol, [2.0, 0.0], 0.8, [1.0], rtol=1e-2, atol=1e-2, first_step=0.8)
    times, _, dense = stepped(DOP853(vdp_python, 0.0, np.array([2.0, 0.0]), 0.8, rtol=1e-2, atol=1e-2, first_step=0.8))
    assert run.n_steps == len(dense) == 1 and run.coefficients.shape == (1, 2, 7)
    t = np.linspace(0.0, 0.8, 9)
    np.testing.assert_allclose(run.dense(t), dense[0](t), rtol=0, atol=1e-14)


def test_a_warm_start_takes_scipys_first_step():
    """first_step given: no initial-step selection (one rhs call fewer), scipy's steps with the same first_step."""
    run = adaptive("RK45", van_der_pol, [2.0, 0.0], 3.0, [1.0], first_step=0.05)
    times, _, _ = stepped(RK45(vdp_python, 0.0, np.array([2.0, 0.0]), 3.0, rtol=1e-6, atol=1e-9, first_step=0.05))
    np.testing.assert_allclose(run.times, times, rtol=1e-7)  # round-off carried by the controller, as above


@pytest.mark.parametrize(
    "method, rtol, error", [("RK45", 1e-9, 1e-7), ("DOP853", 1e-9, 1e-8), ("Rosenbrock23", 1e-7, 5e-4)]
)
def test_the_oscillator_against_its_closed_form(method, rtol, error):
    """x'' = -4 x from x = 1: x = cos 2t, v = -2 sin 2t over 3 periods, ends and dense output."""
    run = adaptive(method, oscillator, [1.0, 0.0], 3 * np.pi, [4.0], rtol=rtol, atol=rtol * 1e-2)
    assert run.status == compiled.REACHED
    np.testing.assert_allclose(run.y_end, [1.0, 0.0], atol=error)
    t = np.linspace(0.0, 3 * np.pi, 37)
    np.testing.assert_allclose(run.dense(t), [np.cos(2 * t), -2 * np.sin(2 * t)], atol=error)


def test_the_stiff_method_is_stable_with_few_steps_and_converges():
    """Eigenvalues -1 and -1e6: an explicit method would need ~3e6 steps over [0, 10]; ode23s's pair stays
    stable in under 200 and matches expm; its error falls by ~(rtol ratio)^(2/3) (order 2, error per step
    h^3) when rtol is tightened 100 times."""
    y0 = np.array([1.0, 0.0])
    errors = []
    for rtol in (1e-4, 1e-6):
        run = adaptive("Rosenbrock23", stiff_linear, y0, 10.0, STIFF.ravel(), rtol=rtol, atol=rtol * 1e-3)
        assert run.status == compiled.REACHED
        t = np.linspace(0.01, 10.0, 50)
        exact = np.column_stack([expm(STIFF * s) @ y0 for s in t])
        errors.append(np.max(np.abs(run.dense(t) - exact)))
        if rtol == 1e-4:
            assert run.n_steps < 200
            assert run.njev == run.n_steps and run.nlu >= run.n_steps
    assert errors[0] < 5e-4
    assert 10.0 < errors[0] / errors[1] < 50.0  # 100^(2/3) = 21.5


def test_the_rosenbrock_steps_are_second_order():
    """All steps accepted at max_step (a huge rtol): halving the step divides the global error by ~4."""
    errors = []
    for step in (0.1, 0.05):
        run = adaptive(
            "Rosenbrock23", oscillator, [1.0, 0.0], 2.0, [1.0], rtol=1e10, atol=1e10, max_step=step, first_step=step
        )
        errors.append(np.max(np.abs(run.y_end - [np.cos(2.0), -np.sin(2.0)])))
    assert errors[0] / errors[1] == pytest.approx(4.0, rel=0.1)


def test_rk4_is_fourth_order_and_the_reference_rk4():
    """Halving the step divides the error by ~16; the same steps, states and Hermite dense output as
    solvers/rk4.py (the step 0.3 shortened to divide [0, 4.1] evenly)."""
    errors = [
        np.max(np.abs(fixed(oscillator, [1.0, 0.0], 2.0, [1.0], step).y_end - [np.cos(2.0), -np.sin(2.0)]))
        for step in (0.1, 0.05)
    ]
    assert errors[0] / errors[1] == pytest.approx(16.0, rel=0.05)
    run = fixed(van_der_pol, [2.0, 0.0], 4.1, [1.0], 0.3)
    times, starts, dense = stepped(RK4(vdp_python, 0.0, np.array([2.0, 0.0]), 4.1, step=0.3))
    np.testing.assert_allclose(run.times, times, rtol=1e-13)
    np.testing.assert_allclose(run.y_old, starts, rtol=1e-13, atol=1e-13)
    inside = times[:-1] + 0.37 * np.diff(times)
    np.testing.assert_allclose(
        run.dense(inside), np.column_stack([d(s) for d, s in zip(dense, inside)]), rtol=1e-13, atol=1e-13
    )
    assert run.nfev == 1 + 4 * run.n_steps


def test_an_event_is_located_to_round_off():
    """x = cos t reaches 0.5 at t = pi/3 (to 1e-12, DOP853 at a tight tolerance); the step ends there."""
    lines = POSITION_LINE.copy()
    lines[0, 1] = -0.5
    run = adaptive("DOP853", oscillator, [1.0, 0.0], 10.0, [1.0, 0.5, np.inf], rtol=1e-13, atol=1e-15, lines=lines)
    assert run.status == compiled.EVENT and run.event_guard == 0
    assert run.event_time == pytest.approx(np.pi / 3, abs=1e-12)
    assert run.t_end == run.event_time
    np.testing.assert_allclose(run.y_end, [0.5, -np.sqrt(0.75)], atol=1e-12)
    np.testing.assert_allclose(run.dense(run.event_time), run.y_end, atol=1e-15)


def reference_misses(start: float, step: float, x) -> bool:
    """The reference's probes of the step [start, start + step] all see x >= 0 (it would miss the dip)."""
    return bool(np.all(x(np.linspace(start, start + step, PROBES_PER_STEP + 2)) >= 0.0))


def test_a_dip_inside_one_step_is_caught_for_a_linear_guard():
    """x = (t - 0.5)^2 - 0.001 dips below 0 on 0.5 -/+ 0.0316 inside the first step [0, 1] of RK45 (exact
    on a parabola, so the step is accepted) between the reference's probes; the polynomial roots find it."""

    def x(t):
        return (t - 0.5) ** 2 - 0.001

    run = adaptive(
        "RK45",
        constant_acceleration,
        [0.249, -1.0],
        10.0,
        [2.0, 0.0, np.inf],
        rtol=1e-3,
        lines=POSITION_LINE,
        first_step=1.0,
    )
    assert run.n_steps == 1 and run.last_step == 1.0 and reference_misses(0.0, 1.0, x)
    assert run.status == compiled.EVENT and run.event_time == pytest.approx(0.5 - np.sqrt(0.001), abs=1e-12)


@pytest.mark.parametrize("level, fires", [(-1e-10, False), (1e-10, True)])
def test_a_near_tangency_fires_only_when_it_dips(level, fires):
    """x = (t - 0.5)^2 against the guard x - level: a parabola that stays 1e-10 above the level holds the mode
    (the exact polynomial roots do not take a near-tangency for a crossing), one that dips 1e-10 below it fires
    where it crosses, t = 0.5 - 1e-5."""
    run = adaptive(
        "RK45",
        constant_acceleration,
        [0.25, -1.0],
        2.0,
        [2.0, level, np.inf],
        lines=np.array([[1.0, -level, 1.0, 0.0]]),
    )
    assert run.status == (compiled.EVENT if fires else compiled.REACHED)
    if fires:
        assert run.event_time == pytest.approx(0.5 - 1e-5, abs=1e-9)


@pytest.mark.parametrize("depth", [0.0064, 1e-4, 1e-8])
def test_a_dip_between_the_reference_probes_is_caught_for_a_nonlinear_guard(depth):
    """exp(x) - 1 with x = (t - 0.5)^2 - depth (below 0 on 0.5 -/+ sqrt(depth): 0.16 s, 0.02 s, 2e-4 s wide) in the
    one RK4 step [0, 1]: all of them between the switch probes (PROBES_PER_STEP) and the two narrower ones between
    any 9 evenly spaced points; the guard's polynomial over the step finds each, Brent's method locates
    t = 0.5 - sqrt(depth)."""

    def x(t):
        return (t - 0.5) ** 2 - depth

    run = fixed(
        constant_acceleration, [x(0.0), -1.0], 1.0, [2.0], 1.0, guards=exponential_position, lines=np.zeros((1, 4))
    )
    assert run.n_steps == 1 and reference_misses(0.0, 1.0, x)
    assert run.status == compiled.EVENT and run.event_time == pytest.approx(0.5 - math.sqrt(depth), abs=1e-12)


def test_a_guard_at_its_boundary_fires_only_past_the_tolerance():
    """x starts at 0 and falls at 1e-13 per s: the guard (threshold 0, or -1e-12 given by the caller) does
    not fire at once but when x < -1e-12 (t = 10 s, or 20 s with the lowered threshold); a threshold of
    0.5 on x = 1 - t fires at t = 0.5."""
    slow = [0.0, -1e-13]
    run = adaptive("RK45", constant_acceleration, slow, 30.0, [0.0, 0.0, np.inf], lines=POSITION_LINE)
    assert run.status == compiled.EVENT and run.n_steps > 0 and run.event_time == pytest.approx(10.0, rel=1e-6)
    run = adaptive(
        "RK45", constant_acceleration, slow, 30.0, [0.0, 0.0, np.inf], lines=POSITION_LINE, thresholds=[-1e-12]
    )
    assert run.status == compiled.EVENT and run.event_time == pytest.approx(20.0, rel=1e-6)
    run = adaptive(
        "RK45", constant_acceleration, [1.0, -1.0], 3.0, [0.0, 0.0, np.inf], lines=POSITION_LINE, thresholds=[0.5]
    )
    assert run.event_time == pytest.approx(0.5, abs=1e-12)


def test_a_guard_already_violated_is_an_event_without_a_step():
    run = adaptive("RK45", oscillator, [-1.0, 0.0], 3.0, [1.0, 0.0, np.inf], lines=POSITION_LINE)
    assert (run.status, run.n_steps, run.event_guard, run.event_time, run.dense) == (compiled.EVENT, 0, 0, 0.0, None)
    np.testing.assert_array_equal(run.y_end, [-1.0, 0.0])


@pytest.mark.parametrize("clock, guard, time", [(1.0, 1, 1.0), (1.1, 0, np.pi / 3)])
def test_the_earliest_of_two_guards_wins(clock, guard, time):
    """x = cos t reaches 0.5 at pi/3 = 1.047 s; the clock guard fires at 1.0 s or 1.1 s."""
    lines = TWO_GUARD_LINES.copy()
    lines[0, 1] = -0.5
    run = adaptive(
        "RK45",
        oscillator,
        [1.0, 0.0],
        5.0,
        [1.0, 0.5, clock],
        rtol=1e-10,
        atol=1e-12,
        guards=position_and_clock,
        lines=lines,
        max_step=0.5,
    )
    assert run.status == compiled.EVENT and run.event_guard == guard
    assert run.event_time == pytest.approx(time, abs=1e-9)


def test_the_wrap_limit_stops_at_the_first_step_end_past_it():
    """x = t with RK4 steps of 1 s and wrap limit 2.5 rad: stops at t = 3 s (status 2)."""
    run = fixed(constant_acceleration, [0.0, 1.0], 10.0, [0.0], 1.0, wrap_limit=2.5)
    assert run.status == compiled.WRAPPED and run.t_end == 3.0 and run.y_end[0] == pytest.approx(3.0)


@pytest.mark.parametrize("method", ["RK45", "DOP853", "RK4"])
def test_a_wrap_inside_the_stepper_is_the_caller_s_restart(method):
    """With wrap_period the stepper wraps the angle itself at the wrap limit; the same as stopping there (status
    2), taking whole periods off the angle and restarting with the last step's size, as the outer loop does:
    the same steps, the unwrapped angle at every step start, the same end state (1e-12), one wrap per restart."""
    period, limit, p, y0, t_end = 2.0 * np.pi, 4 * 2.0 * np.pi, [9.81, 30.0, 40.0], np.array([0.0, 5.0]), 3.0

    def call(y, t0, first_step, wrap_period):
        y = np.asarray(y, dtype=float)
        arguments = (
            rotating_pendulum,
            position,
            0,
            np.zeros((0, 4)),
            np.zeros(0),
            t0,
            y,
            t_end,
            np.asarray(p, dtype=float),
        )
        if method == "RK4":
            return CompiledRun.from_result(
                stepper("RK4")(*arguments, 0.01, limit, wrap_period, 100000, 100000, *NO_RESTARTS)
            )
        return CompiledRun.from_result(
            stepper(method)(
                *arguments[:5],
                position,
                0,
                *arguments[5:],
                1e-8,
                np.full(2, 1e-10),
                np.inf,
                first_step,
                limit,
                wrap_period,
                100000,
                100000,
                *NO_RESTARTS,
            )
        )

    inside = call(y0, 0.0, 0.0, period)
    times, starts, t, y, first_step, offset, restarts = [0.0], [], 0.0, y0, 0.0, 0.0, -1
    while t < t_end:
        restarts += 1
        run = call(y - [offset, 0.0], t, first_step, 0.0)
        assert run.status == (compiled.REACHED if run.t_end == t_end else compiled.WRAPPED)
        times += list(run.times[1:])
        starts += list(run.y_old + [offset, 0.0])
        t, y = run.t_end, run.y_end + [offset, 0.0]
        first_step = min(run.last_step, t_end - t)
        offset = period * np.floor(y[0] / period)
    assert inside.status == compiled.REACHED and inside.wraps == restarts >= 3 and inside.y_end[0] > 3 * limit
    np.testing.assert_allclose(inside.times, times, rtol=1e-12, atol=0)
    np.testing.assert_allclose(inside.y_old, starts, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(inside.y_end, y, rtol=1e-12)


def test_failures_keep_what_was_computed():
    """y' = y^2 escapes at t = 1: RK4 (stepping just past it) reports a non-finite state, RK45 a step size
    underflow just past it, both with the steps taken kept; max_steps is a failure too."""
    fixed_run = fixed(blow_up, [1.0], 2.0, [0.0], 0.01)
    assert fixed_run.status == compiled.FAILED and fixed_run.failure == compiled.NONFINITE
    assert 0.99 < fixed_run.t_end < 1.1 and "non-finite" in fixed_run.message and np.all(np.isfinite(fixed_run.y_old))
    adaptive_run = adaptive("RK45", blow_up, [1.0], 2.0, [0.0])
    assert adaptive_run.status == compiled.FAILED and adaptive_run.failure == compiled.STEP_TOO_SMALL
    assert 0.99 < adaptive_run.t_end < 1.01 and "step size" in adaptive_run.message
    limited = adaptive("RK45", oscillator, [1.0, 0.0], 100.0, [1.0], max_steps=5)
    assert (limited.status, limited.failure, limited.n_steps) == (compiled.FAILED, compiled.TOO_MANY_STEPS, 5)
    run_limited = adaptive("RK45", oscillator, [1.0, 0.0], 100.0, [1.0], run_steps=7)
    assert (run_limited.status, run_limited.failure, run_limited.n_steps) == (
        compiled.FAILED,
        compiled.TOO_MANY_STEPS,
        7,
    )


@pytest.mark.parametrize("method", ["RK45", "DOP853", "RK4"])
def test_a_speed_beyond_the_limit_stops_the_call_at_that_step(method):
    """y' = y^2 (y a speed: speed_indices [0]) passes MAX_SPEED = 1e6 just before t = 1: the call stops at the first
    step end beyond it, that step kept: the same steps as the call without the check, up to that one."""
    watched = list(NO_RESTARTS)
    watched[4] = np.zeros(1, dtype=np.int64)  # speed_indices
    if method == "RK4":
        free, stopped = (
            fixed(blow_up, [1.0], 2.0, [0.0], 1e-4, restarts=restarts) for restarts in (NO_RESTARTS, tuple(watched))
        )
    else:
        free, stopped = (
            adaptive(method, blow_up, [1.0], 2.0, [0.0], restarts=restarts)
            for restarts in (NO_RESTARTS, tuple(watched))
        )
    ends = np.append(free.y_old[1:, 0], free.y_end[0])
    first = int(np.argmax(ends > 1e6))  # the first step end beyond the limit
    assert 0 < first < free.n_steps - 1 and free.beyond == -1
    assert (stopped.status, stopped.failure, stopped.beyond) == (compiled.FAILED, compiled.BLOWN_UP, 0)
    assert stopped.n_steps == first + 1 and np.array_equal(stopped.times, free.times[: first + 2])
    assert stopped.y_end[0] == ends[first] > 1e6 >= stopped.y_old[-1, 0]


def test_the_dense_output_of_a_call_on_scalars_and_arrays():
    """StepsDense: shape (n,) for a scalar, (n, m) for m times; the step starts give y_old and the end y_end;
    the arrays grew past their first capacity."""
    run = adaptive("RK45", oscillator, [1.0, 0.0], 6.0, [1.0], rtol=1e-8, atol=1e-10)
    assert run.n_steps > 16
    dense = run.dense
    assert isinstance(dense, StepsDense) and dense(1.0).shape == (2,) and dense(np.array([1.0, 2.0])).shape == (2, 2)
    np.testing.assert_allclose(dense(run.times[:-1]), run.y_old.T, atol=1e-15)
    np.testing.assert_allclose(dense(6.0), run.y_end, atol=1e-14)
    np.testing.assert_allclose(dense(1.0), [np.cos(1.0), -np.sin(1.0)], atol=1e-7)


def test_the_compiled_dense_output_gives_numpys_numbers_to_the_bit():
    """StepsDense's evaluation (compiled: solvers/compiled/dense.py) is the numpy formula of its docstring to the bit,
    Horner's scheme from the highest coefficient, at step starts with and without a restart there (a restarted step's
    start answered by the step before), inside the steps, beyond both ends and with phi's whole periods added back."""
    rng = np.random.default_rng(35)
    n_steps, n_states, order = 9, 3, 7
    times = np.cumsum(rng.uniform(1e-4, 2e-3, n_steps + 1))
    y_old, coefficients = rng.normal(size=(n_steps, n_states)), rng.normal(size=(n_steps, n_states, order))
    offsets, restarted = rng.choice([0.0, 2 * np.pi, 4 * np.pi], n_steps), np.arange(n_steps) % 3 == 2
    at = np.concatenate([times, rng.uniform(times[0] - 1e-3, times[-1] + 1e-3, 40)])

    k = np.clip(np.searchsorted(times, at, side="right") - 1, 0, n_steps - 1)
    k -= restarted[k] & (times[k] == at)
    h = times[k + 1] - times[k]
    theta = ((at - times[k]) / h)[:, None]
    total = np.zeros((at.size, n_states))
    for j in range(order - 1, -1, -1):
        total += coefficients[k][:, :, j]
        total *= theta
    expected = (y_old[k] + h[:, None] * total).T
    expected[0] += offsets[k]

    dense = StepsDense(times, y_old, coefficients, offsets, restarted)
    assert np.array_equal(dense(at), expected) and np.array_equal(dense(at[3]), expected[:, 3])
    assert not np.array_equal(expected, StepsDense(times, y_old, coefficients)(at))  # the offsets and restarts count


@pytest.mark.parametrize("method", ["RK45", "DOP853", "Rosenbrock23"])
def test_the_steps_keep_their_reach_from_a_reaction_passing_near_zero(method):
    """y' = |R(t)| with |R|^2 = R_m^2 + R'^2 (t - t_m)^2 (1.4 N at its minimum at t_m = 0.113 s, R' = 2e4 N/s, the
    compressor's wrist pin): |R| has branch points at t_m +- i a, a = R_m / R' = 70 us. With the journal's |R|^2 given
    (reactions, n_journals 1) every accepted step stays at least its own length away from them (its distance to
    them over its length >= 1 less round-off), and y(0.3 s) meets the closed form y = R'/2 [u sqrt(a^2 + u^2) +
    a^2 asinh(u / a)] from u = -t_m to 0.3 s - t_m within rtol; without (n_journals 0) RK45 and DOP853 take a step
    within a tenth of its length of them (measured 0.015 and 0.019 of it, 7 and 0.3 rtol off)."""
    p, rtol = [1.4, 2.0e4, 0.113], 1e-6
    a = p[0] / p[1]

    def exact(t):
        u = t - p[2]
        return 0.5 * p[1] * (u * math.sqrt(a * a + u * u) + a * a * math.asinh(u / a))

    def distance_over_length(run):  # the steps' distance to t_m + i a over their length
        starts, ends = run.times[:-1], run.times[1:]
        beside = (starts <= p[2]) & (p[2] <= ends)
        return np.where(beside, a, np.minimum(np.hypot(starts - p[2], a), np.hypot(ends - p[2], a))) / (ends - starts)

    run = adaptive(method, reaction_size, [0.0], 0.3, p, rtol=rtol, atol=rtol, reactions=reaction_square, n_journals=1)
    assert run.status == compiled.REACHED and np.min(distance_over_length(run)) >= 1.0 - 1e-7
    assert abs(run.y_end[0] - (exact(0.3) - exact(0.0))) <= rtol * (exact(0.3) - exact(0.0))
    if method != "Rosenbrock23":  # its third-order steps stay short enough there on their own
        free = adaptive(method, reaction_size, [0.0], 0.3, p, rtol=rtol, atol=rtol, reactions=reaction_square)
        assert np.min(distance_over_length(free)) < 0.1


def test_a_trajectory_of_compiled_pieces_answers_scalars_lists_and_arrays_and_refuses_what_it_dropped():
    """Trajectory's evaluation (solvers/trajectory.py) over compiled calls' pieces (StepsDense): a scalar time gives the
    state, a list or an array of times one column each, with one piece as with several (scipy's OdeSolution); once a
    stream dropped the first piece, a time before what is kept is refused with a message naming it."""
    times = np.array([0.0, 1.0, 2.0])
    y_old, coefficients = np.array([[1.0, 2.0], [3.0, 4.0]]), np.ones((2, 2, 1))  # y = y_old + h theta on each step
    first = StepsDense(times, y_old, coefficients)
    second = StepsDense(times + 2.0, y_old + 4.0, coefficients)
    trajectory = Trajectory(method="DOP853", t_start=0.0)
    trajectory.add_piece(0.0, 2.0, first, step_ends=times[1:])
    assert np.array_equal(trajectory(0.5), [1.5, 2.5])
    assert np.array_equal(trajectory([0.5, 1.5]), [[1.5, 3.5], [2.5, 4.5]])
    trajectory.add_piece(2.0, 4.0, second, step_ends=times[1:] + 2.0)
    assert np.array_equal(trajectory(3.5), [7.5, 8.5])
    assert np.array_equal(trajectory(np.array([0.5, 3.5])), [[1.5, 7.5], [2.5, 8.5]])
    trajectory.drop_front(1)
    assert np.array_equal(trajectory([2.5]), [[5.5], [6.5]])
    with pytest.raises(ValueError, match=r"t = 0.5 s: the trajectory holds only t >= 2.0 s"):
        trajectory(0.5)
