"""Integration in time: scipy's adaptive OdeSolver classes (RK45, RK23, DOP853, Radau, BDF, LSODA)
stepped one step at a time, and the classic fixed-step RK4.

Load changes in time are breakpoints: each external-load piece is integrated on its own, so no step
straddles a jump or a kink. Moments that jump with the crank angle (an on-off cutting load) are
switches: every accepted step is checked for a crossing of a switch angle, also inside the step
(the dense output is probed at interior points, so a step that crosses and comes back is caught),
the crossing is located on the dense output, and the solver restarts exactly on the switch.
With joint friction, every step of an adaptive one-step method also stays at least its own length away from
the branch points of the journals' friction |R_j| in complex time (_reaction_branches), where a reaction passes
close to zero and the method's error estimate would not see it.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable

import numpy as np
from scipy import integrate, optimize
from scipy.integrate._ivp.rk import Dop853DenseOutput

from mech_regulator.governors import Guard
from mech_regulator.model import MachineModel
from mech_regulator.scene.limits import MAX_SPEED, MAX_STEPS, speed_beyond_limit
from mech_regulator.solvers.cam_contact import ContactLost, ContactWatch
from mech_regulator.solvers.rk4 import RK4
from mech_regulator.solvers.trajectory import Progress, Stream, Trajectory

PROBES_PER_STEP = 4  # interior points of each step checked for a switch crossing
RESTART_PERIODS = 4  # the solver's wrapped crank angle stays within this many dynamic periods
MAX_INSTANT_EVENTS = 20  # governor mode changes allowed at one instant before the run is declared stuck
MAX_RESTARTS_WITHOUT_PROGRESS = 100  # restarts in a row of any kind (switch, table piece, guide, mode, wrap) at one
# instant before the run is declared stuck (fail_no_progress): a loop that makes no progress in time never spins
GUARD_TOLERANCE = 1e-12  # a guard within this of 0 (in its own units: rad, rad/s, N, 1/s) is at its boundary
# one-step methods: on a switch or kink they restart from a step onto it, not from the dense output (_step_onto)
STEPS_ONTO_SWITCHES = ("RK23", "RK45", "DOP853", "Radau", "RK4")
# multistep methods restart at order 1: a restart on every kink of a table (24 a turn on an engine) costs them more
# accuracy than stepping over the kinks, so they restart on switch angles (jumps) only
STEPS_OVER_KINKS = ("BDF", "LSODA")
# adaptive one-step methods: every step stays at least its own length away from the branch points of the journals'
# friction |R_j(t)| in complex time (_reaction_branches, _reach); the multistep methods step over corners, RK4 keeps
# its step
STEPS_WITHIN_REACTIONS = ("RK23", "RK45", "DOP853", "Radau")
GUARD_NODES = 9  # a guard along a step is interpolated at this many Chebyshev points (time_domain.guard_polynomial)
GUARD_NODE_FRACTIONS = 0.5 - 0.5 * np.cos(np.pi * np.arange(GUARD_NODES) / (GUARD_NODES - 1))  # theta_k in [0, 1]
SAMPLES_TO_POWERS = np.linalg.inv(np.vander(GUARD_NODE_FRACTIONS, increasing=True))  # samples -> powers of theta
# a zero of a journal's |R_j|^2 along a step within this much of the real axis (in theta, units of the step) is real:
# a reaction through 0 (a corner of |R_j|; its double zero splits by some sqrt(eps) in round-off), not a branch point
REAL_ZERO = 1e-7
# samples -> the interpolant's last Chebyshev coefficient, (1 / (n - 1)) sum'' (-1)^k g_k (ends halved), up to sign
LAST_CHEBYSHEV = (-1.0) ** np.arange(GUARD_NODES) * np.r_[0.5, np.ones(GUARD_NODES - 2), 0.5] / (GUARD_NODES - 1)


def integrate_time_domain(
    model: MachineModel, progress: Progress | None = None, segment=None, stream: Stream | None = None
) -> Trajectory:
    """Integrate the scene's scenario with its solver settings; returns the (possibly partial) trajectory.
    segment: what steps one external-load piece, with _segment's arguments and result (default _segment, the
    reference path; the fast path passes its compiled twin, solvers/compiled/run.py); stream: the trajectory's
    (Trajectory.stream)."""
    segment = segment or _segment
    solver = model.scene.solver
    scenario = model.scene.scenario
    y = model.initial_state()
    watch = ContactWatch(model, stream)  # a cam follower that jumps ends the run there, found as the steps come
    trajectory = Trajectory(method=solver.method, t_start=0.0, y_start=y.copy(), stream=watch.stream)
    mode = model.initial_mode(y)
    if mode is not None:
        trajectory.modes.append((0.0, mode))
    edges = [0.0] + [t for t in model.breakpoints() if 0.0 < t < scenario.duration] + [scenario.duration]
    try:
        for t_start, t_end in zip(edges[:-1], edges[1:]):
            try:
                y, mode = segment(model, model.piece_at(t_start), t_start, t_end, y, mode, trajectory, progress)
                watch.check(trajectory)  # the piece's steps not checked yet
            except ContactLost:  # the trajectory ends where the contact was lost (solvers/cam_contact.py)
                break
            if trajectory.status != "complete":
                break
        trajectory.stats.restarts += len(edges) - 2
    except KeyboardInterrupt:
        trajectory.status = "interrupted"
        trajectory.message = f"interrupted by the user at t = {trajectory.t_end:.6g} s"
    return trajectory


def _segment(
    model: MachineModel,
    piece,
    t_start: float,
    t_end: float,
    y: np.ndarray,
    mode,
    trajectory: Trajectory,
    progress: Progress | None,
) -> tuple[np.ndarray, tuple | None]:
    """Step the scene's solver over [t_start, t_end], restarting it exactly at every switch crossing and
    every governor event; returns the state and mode at the end.

    When something depends on phi, the solver integrates the crank angle wrapped by whole dynamic
    periods (the right-hand side is periodic in them): a growing phi would otherwise loosen the
    relative tolerance on the phase step by step. It restarts, keeping its step size, whenever the
    wrapped angle passes RESTART_PERIODS periods; outputs carry the unwrapped angle.
    """
    settings = model.scene.solver
    kinks = settings.method not in STEPS_OVER_KINKS
    grid = np.array(model.switch_grid(kinks), dtype=float)
    period = model.dynamic_period()
    # each angle of the grid once per dynamic period: a friction corner on a table's knot (their own periods differ)
    # is one switch, as on the fast path, not two crossings at the same point
    switches = np.column_stack((grid, np.full(grid.size, period)))
    wraps = model.reduced is not None or "phi" in model.depends_on()  # else phi is only an output
    names = model.state_names()
    t, first_step = t_start, None
    # the crank angle as whole periods and the phase within them (turns_and_phase), carried exactly across the
    # restarts; the switch counts are the phase's (relative to turns)
    turns, phase = turns_and_phase(y[0], period) if wraps else (0, float(y[0]))  # (phi only an output)
    counts = _switch_counts(phase, switches)
    tables = model.state_tables if kinks else ()
    held: list[int] = []  # per state table its piece, counted from the carried turns (_held_pieces; none yet)
    normal_sides: tuple[float, ...] = ()  # joint friction's guides: the held signs of N,
    crossed_normal: int | None = None  # and the one just crossed
    journals = _journals(model) if settings.method in STEPS_WITHIN_REACTIONS else ()
    branches = np.empty(0, dtype=complex)  # the branch points of the journals' |R_j| the last step saw [s]
    instant_events = 0  # mode changes in a row that the solver located at its own start: no time passed
    stalled = 0  # restarts in a row of any kind that left the time where it was
    while t < t_end and trajectory.status == "complete":
        if wraps:
            whole = math.floor(phase / period)
            turns, phase = turns + whole, phase - whole * period
            counts = [count - whole for count in counts]
            held = _unwound_pieces(tables, held, whole, period)
        offset = turns * period if wraps else 0.0
        y, mode, phase = settle_mode_in_phase(model, t, y, phase, offset, mode, trajectory)
        if trajectory.status != "complete":
            break
        y_wrapped = y.copy()
        y_wrapped[0] = phase
        held = _held_pieces(tables, y_wrapped, held)
        breakpoints = _breakpoint_guards(tables, held, mode, y_wrapped)
        guards = model.guards(mode, y) + list(breakpoints)
        window = switch_window(grid, period, phase, forward=y[1] >= 0.0) if grid.size else None
        anchors = _anchors(tables, held) if tables else None  # those of an angular table in the solver's phi
        normal_sides, normal_guards = _normal_guards(
            model, piece, window, mode, kinks, anchors, t, y_wrapped, normal_sides, crossed_normal
        )
        crossed_normal = None
        guards += list(normal_guards)
        rhs = model.rhs(piece, window, mode, kinks=kinks, anchors=anchors, normal_signs=normal_sides)
        reactions = model.joint_reactions(piece, window, mode, kinks, anchors, normal_sides) if journals else None
        constraint = model.constraint(mode)
        interpolant_noise = (settings.atol + settings.rtol * np.abs(y_wrapped)) if settings.method == "Radau" else None
        if branches.size and first_step is not None:  # a restart's first step stays within the reach too
            first_step = min(first_step, max(_reach(branches, t), _smallest_limit(t)))
        solver = _solver(settings, rhs, t, y_wrapped, t_end, first_step)
        restart, redone, crossing = False, False, None
        while solver.status == "running" and not restart:
            try:
                message = solver.step()
            except (ValueError, ArithmeticError, np.linalg.LinAlgError) as error:  # e.g. an implicit method's
                trajectory.status = "failed"  # Jacobian overflowing: a numerical breakdown, reported as a failure
                trajectory.message = (
                    f"{settings.method} failed at t = {solver.t:.6g} s: {error} (the state: "
                    f"{state_text(names, y)}); the numbers of the machine overflow the method"
                )
                break
            if solver.status == "failed":
                trajectory.status = "failed"
                trajectory.message = f"{settings.method} failed at t = {solver.t:.6g} s: {message}"
                break
            if not np.all(np.isfinite(solver.y)):
                trajectory.status = "failed"
                advice = "use a smaller step" if settings.method == "RK4" else "tighten rtol/atol or limit max_step"
                trajectory.message = (
                    f"{settings.method}: the state became non-finite at t = {solver.t:.6g} s; "
                    f"{advice} (the last finite state, at t = {t:.6g} s: {state_text(names, y)})"
                )
                break
            wrapped = _Shifted(solver.dense_output(), 0.0, constraint)
            dense = _Shifted(wrapped.dense, offset, constraint)
            t_step, y_step, phase_step = solver.t, dense(solver.t), solver.y[0]
            beyond = speed_beyond_limit(names, y_step)
            if beyond is not None:  # the step that carried it there is kept, to show the blow-up
                trajectory.add_piece(solver.t_old, t_step, dense)
                trajectory.stats.steps += 1
                fail_blown_up(model, trajectory, t_step, y_step, *beyond)
                break
            if journals:
                branches = _reaction_branches(reactions, journals, wrapped, solver.t_old, solver.t)
                longest = _reach(branches, solver.t_old)
                if solver.t - solver.t_old > longest and not redone:  # the step again, within the reach
                    _count_evaluations(trajectory, solver)
                    y_start = np.array(y, dtype=float)
                    y_start[0] = phase
                    solver = _solver(settings, rhs, t, y_start, t_end, max(longest, _smallest_limit(t)))
                    redone = True
                    continue
                redone = False
                solver.max_step = min(
                    settings.max_step or np.inf, max(_reach(branches, solver.t), _smallest_limit(solver.t))
                )
            if len(switches) or guards:
                crossing = _first_event(
                    dense, solver.t_old, solver.t, counts, switches, guards, interpolant_noise, wrapped=wrapped
                )
                if crossing is not None:
                    t_step, y_step, counts, guard, name, phase_step = crossing
                    if guard is None:
                        trajectory.stats.switches += 1
                        if settings.method in STEPS_ONTO_SWITCHES and t_step > solver.t_old:
                            dense, y_step, phase_step = _step_onto(
                                settings,
                                rhs,
                                solver.t_old,
                                y,
                                phase,
                                t_step,
                                offset,
                                constraint,
                                phase_step,
                                trajectory,
                            )
                    elif guard in breakpoints or guard in normal_guards:  # a table's breakpoint or a guide's N = 0:
                        trajectory.stats.switches += 1  # the next piece, mode and state kept
                        if guard in normal_guards:
                            crossed_normal = normal_guards[guard]
                            normal_sides = tuple(
                                -side if k == crossed_normal else side for k, side in enumerate(normal_sides)
                            )
                        else:
                            table, step = breakpoints[guard]
                            held[table] += step
                        if settings.method in STEPS_ONTO_SWITCHES and t_step > solver.t_old:
                            dense, y_step, phase_step = _step_onto(
                                settings, rhs, solver.t_old, y, phase, t_step, offset, constraint, None, trajectory
                            )
                    else:
                        mode, y_step = guard.apply(t_step, y_step)
                        y_step = np.array(y_step, dtype=float)
                        y_step[0] = offset + phase_step  # (a transition never moves the crank)
                        _log_event(trajectory, t_step, name, mode)
                        instant_events = instant_events + 1 if t_step == solver.t_old == t else 0
                        if instant_events > MAX_INSTANT_EVENTS:
                            _fail_stuck(trajectory, t_step)
                    restart = t_step < t_end or guard is not None
            trajectory.add_piece(solver.t_old, t_step, dense)
            trajectory.stats.steps += 1
            stalled = stalled + 1 if t_step == t else 0
            t, y, phase = t_step, np.array(y_step, dtype=float), phase_step
            if trajectory.stats.steps >= MAX_STEPS:
                fail_too_many_steps(model, trajectory, t, y)
                break
            if stalled >= MAX_RESTARTS_WITHOUT_PROGRESS:
                fail_no_progress(model, trajectory, t, y, f"the event '{name}'" if crossing else "a step")
                break
            restart = restart or (wraps and abs(solver.y[0]) > RESTART_PERIODS * period and t < t_end)
            if progress is not None:
                progress(t)
        first_step = min(solver.step_size, t_end - t) if solver.step_size else None
        _count_evaluations(trajectory, solver)
        if restart:
            trajectory.stats.restarts += 1
    return y, mode


def _break(table, i: int) -> float:
    """The table's i-th breakpoint on the line of its value: breaks[i] (-inf below the first, inf above the last);
    periodic, breaks[i mod n] + period (i div n) (n breaks a period)."""
    n = len(table.breaks)
    if table.period is not None:
        return table.breaks[i % n] + table.period * (i // n)
    return table.breaks[i] if 0 <= i < n else -math.inf if i < 0 else math.inf


def _held_pieces(tables, y: np.ndarray, held: list[int] | None = None) -> list[int]:
    """For each StateTable, the piece its value(y) is in: i such that _break(i - 1) <= value < _break(i) (0 and
    len(breaks) the ends of a table without period). y is the state as the solver steps it, phi the phase within
    the carried turns (turns_and_phase): a table that turns with phi (angular, phi2 = phi - twist) is read on the
    phase and its pieces counted from the turns, so its breakpoints keep their precision however far phi grows
    (docs/hard_cases.md, "Long runs"). A carried piece (held) is kept while the value stays in it to within 1e-9 of
    the breaks' size: a restart just on a breakpoint then stays on the side the crossing went to (None or []: none
    carried)."""
    pieces = []
    for k, table in enumerate(tables):
        value, breaks = table.value(y), table.breaks
        if held:
            size = max(max(abs(b) for b in breaks), breaks[-1] - breaks[0], table.period or 0.0)
            slack = 1e-9 * size or 1e-15
            if _break(table, held[k] - 1) - slack <= value <= _break(table, held[k]) + slack:
                pieces.append(held[k])
                continue
        if table.period is None:
            pieces.append(bisect.bisect_right(breaks, value))
        else:
            turns = math.floor(value / table.period)
            pieces.append(turns * len(breaks) + bisect.bisect_right(breaks, value - turns * table.period))
    return pieces


def _unwound_pieces(tables, held: list[int], whole: int, period: float) -> list[int]:
    """The held pieces (_held_pieces; [] none yet) once `whole` dynamic periods (period [rad]) came off the phase: an
    angular table's (its period a whole part of the dynamic period, MachineModel.dynamic_period) counts back its
    pieces in them, the others' stay."""
    return [
        i - whole * round(period / table.period) * len(table.breaks) if table.angular else i
        for table, i in zip(tables, held)
    ]


def _anchors(tables, held: list[int]) -> tuple[float, ...]:
    """A value strictly inside each table's held piece (its middle, 1 unit beyond an end break for an end piece): the
    rhs's anchors."""
    anchors = []
    for table, i in zip(tables, held):
        low, high = _break(table, i - 1), _break(table, i)
        anchors.append(high - 1.0 if low == -math.inf else low + 1.0 if high == math.inf else 0.5 * (low + high))
    return tuple(anchors)


def _breakpoint_guards(tables, held: list[int], mode, y: np.ndarray) -> dict:
    """The guards of the breakpoints around each table's held piece, from the state y the solver starts at:
    value - breaks[i - 1] >= 0 and breaks[i] - value >= 0 (those that exist), each mapped to (table index, the piece
    step its crossing makes: -1 or +1). They change no mode; their crossing restarts the solver on the next piece. A
    start just across the breakpoint it was stepped onto (within _held_pieces' slack, the method's error) moves that
    level to the start value: the guard starts at its boundary, instead of firing again at once. The guards, y and
    the pieces are those of the state as the solver steps it (phi the phase, _held_pieces)."""
    guards = {}
    for k, (table, i) in enumerate(zip(tables, held)):
        start, below, above = table.value(y), _break(table, i - 1), _break(table, i)
        if below > -math.inf:
            low = min(below, start)
            guards[
                Guard(
                    f"{table.name} breakpoint {below:g}",
                    lambda state, value=table.value, low=low: value(state) - low,
                    lambda state: (mode, state),
                )
            ] = (k, -1)
        if above < math.inf:
            high = max(above, start)
            guards[
                Guard(
                    f"{table.name} breakpoint {above:g}",
                    lambda state, value=table.value, high=high: high - value(state),
                    lambda state: (mode, state),
                )
            ] = (k, +1)
    return guards


def _normal_guards(
    model: MachineModel,
    piece,
    window,
    mode,
    kinks: bool,
    anchors,
    t: float,
    y: np.ndarray,
    sides: tuple[float, ...],
    crossed: int | None,
) -> tuple[tuple[float, ...], dict[Guard, int]]:
    """Joint friction's guides at a restart (t [s], y with phi in the phase, as the solver steps it and the guards read
    it): (the signs s of their normal
    forces N that the rhs holds, normal_signs, and the guards s N >= 0 whose crossing flips one, each with its
    guide's number), or ((), {}) for a machine without a guide with friction or a multistep method (kinks False: it
    steps over kinks, N's too). A sign is N's at the start, or, for the guide whose guard just crossed (crossed, its
    number), the side it crossed to (sides, already flipped); that guard's level then starts at the start's value
    when that is within the method's error across 0 (as _breakpoint_guards), instead of firing again at once."""
    friction = model.joint_friction if kinks else None
    count = len(friction.guides) if friction is not None else 0
    if friction is None or count == 0:
        return (), {}

    def normal_of(guide: int, signs: tuple[float, ...]) -> Callable[[float, np.ndarray], float]:
        """(t, y) -> N [N] of a guide with friction (guide < count), the rhs holding the signs of N."""
        normal = model.guide_normal(piece, window, mode, kinks, anchors, normal_signs=signs, guide=guide)
        assert normal is not None, "a guide of joint_friction.guides has friction"
        return normal

    sides = tuple(
        side if k == crossed else 1.0 if normal_of(k, ())(t, y) >= 0.0 else -1.0
        for k, side in enumerate(sides or (0.0,) * count)
    )
    guards = {}
    for k, side in enumerate(sides):
        normal = normal_of(k, sides)
        low = min(0.0, side * normal(t, y))

        def level(tau: float, state: np.ndarray, side: float = side, normal=normal, low: float = low) -> float:
            return side * normal(tau, state) - low

        name = f"{friction.names[friction.guides[k]]}'s normal force changes sign"
        guards[Guard(name, level, lambda tau, state: (mode, state), timed=True)] = k
    return sides, guards


def _solver(settings, rhs, t: float, y: np.ndarray, t_bound: float, first_step: float | None):
    """The scene's solver (scipy's OdeSolver class of settings.method, or RK4) started at (t [s], y) towards t_bound."""
    if settings.method == "RK4":
        return RK4(rhs, t, y, t_bound, step=settings.step)
    return getattr(integrate, settings.method)(
        rhs,
        t,
        y,
        t_bound,
        rtol=settings.rtol,
        atol=settings.atol,
        max_step=settings.max_step or np.inf,
        first_step=first_step,
    )


def _count_evaluations(trajectory: Trajectory, solver) -> None:
    """Add a solver's function evaluations, Jacobians and LU decompositions to the trajectory's statistics."""
    trajectory.stats.nfev += int(solver.nfev)
    trajectory.stats.njev += int(solver.njev)
    trajectory.stats.nlu += int(solver.nlu)


def _journals(model: MachineModel) -> tuple[int, ...]:
    """The joints with friction whose |R_j| the right-hand side reads as it is (journals; not the guides, whose |N| it
    reads as s_N N between located crossings): their positions in joint_friction.names, or () without joint friction
    on a mechanism."""
    friction = model.joint_friction
    if friction is None or friction.loads is None:
        return ()
    return tuple(k for k in range(len(friction.names)) if k not in friction.guides)


def _reaction_branches(reactions, journals: tuple[int, ...], wrapped, t_old: float, t_new: float) -> np.ndarray:
    """The branch points [s, complex] of the journals' friction rho_j |R_j| seen along the step (t_old, t_new] [s]: the
    complex zeros of |R_j(t)|^2, where |R_j| = sqrt(|R_j|^2) stops being analytic. Where a reaction passes close to 0
    without a sign change to locate (R = R_m + R' (t - t_m), R_m perpendicular to R'), |R_j|^2 = |R_m|^2 +
    |R'|^2 (t - t_m)^2 has its zeros at t_m +- i |R_m| / |R'|: the motion's Taylor series about a point converges
    only within its distance to them, and a one-step method's error estimate, an expansion in the step, fails on
    steps that reach that far (DOP853 accepted a 23 ms step across the wrist pin's 1.4 N of 145 N with 14 times its
    tolerance); _reach gives the steps that do not. |R_j|^2 along the step: reactions(t, y) (the segment's
    MachineModel.joint_reactions, in the solver's phi) at the journals' positions, on the solver's own dense output
    (wrapped: phi in the phase, as the solver steps it) at the GUARD_NODES Chebyshev points (_branch_points). They are
    the reactions the step integrates, continued along the segment: beyond a corner inside the step (which the step is
    then cut at) the reactions themselves have a kink, whose interpolant's complex zeros would limit the step for
    nothing."""
    h = t_new - t_old
    times = t_old + GUARD_NODE_FRACTIONS * h
    states = wrapped(times)
    sizes = np.array([reactions(time, states[:, k]) for k, time in enumerate(times)])
    return _branch_points(sizes[:, list(journals)] ** 2, t_old, h)


def _branch_points(squares: np.ndarray, t_old: float, h: float) -> np.ndarray:
    """The branch points [s, complex] of the journals' |R_j| along the step (t_old, t_old + h] [s] from squares[k, j],
    |R_j|^2 [N^2] at the GUARD_NODES Chebyshev points t_old + GUARD_NODE_FRACTIONS[k] h: the complex zeros of each
    journal's interpolating polynomial in theta = (t - t_old) / h (np.roots), as times t_old + h theta. Zeros within
    REAL_ZERO of the real axis (a reaction through 0: a corner of |R_j|, nothing to step around) are left out, and so
    is a journal with a non-finite sample (the step fails on its own). Plain loops: the fast path compiles it
    (solvers/compiled/events.py)."""
    found = np.empty(squares.shape[1] * (GUARD_NODES - 1), dtype=np.complex128)
    count = 0
    for j in range(squares.shape[1]):
        samples = np.ascontiguousarray(squares[:, j])
        if not np.all(np.isfinite(samples)):
            continue
        powers = SAMPLES_TO_POWERS @ samples
        for root in np.roots(powers[::-1].astype(np.complex128)):  # complex: numba keeps the domain
            if abs(root.imag) > REAL_ZERO:
                found[count] = t_old + h * root
                count += 1
    return found[:count]


def _reach(branches: np.ndarray, t: float) -> float:
    """The longest step h [s] forward from t [s] whose every point lies at least h away from every branch point
    (_branch_points) x + i rho [s] (x relative to t): |x + i rho| for one behind (x <= 0); |x + i rho|^2 / (2 x) when
    rho <= x (the step's end then h from it); else rho (it lies beside the step); inf without any. Plain loops: the
    fast path compiles it."""
    longest = math.inf
    for branch in branches:
        x, rho = branch.real - t, abs(branch.imag)
        if x <= 0.0:
            longest = min(longest, math.hypot(x, rho))
        else:
            longest = min(longest, (x * x + rho * rho) / (2.0 * x) if rho <= x else rho)
    return longest


def _smallest_limit(t: float) -> float:
    """The shortest step limit [s] given to scipy's solvers at time t [s]: 100 times the spacing of floating-point
    numbers at |t| + 1 (scipy's own smallest step is 10 times the spacing at t; a limit below it fails the run)."""
    return 100.0 * float(np.spacing(abs(t) + 1.0))


def _step_onto(
    settings,
    rhs,
    t_old: float,
    y_old: np.ndarray,
    phase_old: float,
    t_switch: float,
    offset: float,
    constraint,
    phase_switch: float | None,
    trajectory: Trajectory,
) -> tuple:
    """Step from the accepted step's start (t_old [s], y_old unwrapped, its crank phase phase_old = phi less offset
    [rad]) exactly onto the switch crossing located at
    t_switch [s] (a step of t_switch - t_old, with the same rhs: RK4 one step, an adaptive method its own steps,
    normally one): the state there then has the method's step accuracy, where the dense output's (the crossing's
    location) is not controlled at all; restarting on knots from the dense output loses about a digit over a run (an
    engine at rtol 1e-10: 2-10 rtol instead of 0.3-0.8). Returns (the dense output over (t_old, t_switch], the state
    at t_switch with the phase set to the switch angle phase_switch [rad, less offset], or as the step ends for None: a
    table's breakpoint crossed by a function of the state; the phase there); the function evaluations count in
    trajectory."""
    start = np.array(y_old, dtype=float)
    start[0] = phase_old
    onto = _solver(settings, rhs, t_old, start, t_switch, t_switch - t_old)
    pieces = []
    while onto.status == "running":
        onto.step()
        pieces.append(_Shifted(onto.dense_output(), offset, constraint))
    _count_evaluations(trajectory, onto)
    phase = onto.y[0] if phase_switch is None else phase_switch
    y_switch = pieces[-1](t_switch)
    y_switch[0] = offset + phase
    return (pieces[0] if len(pieces) == 1 else _Joined(pieces)), y_switch, phase


class _Joined:
    """Dense outputs of consecutive steps as one function of time (each called on its own interval)."""

    def __init__(self, pieces: list):
        self.pieces = pieces
        self.ends = [piece.dense.t for piece in pieces]

    def __call__(self, t):
        times = np.atleast_1d(np.asarray(t, dtype=float))
        indices = np.minimum(np.searchsorted(self.ends, times), len(self.pieces) - 1)
        columns = np.column_stack([self.pieces[i](tau) for i, tau in zip(indices, times)])
        return columns[:, 0] if np.ndim(t) == 0 else columns


def settle_mode_in_phase(
    model: MachineModel, t: float, y: np.ndarray, phase: float, offset: float, mode, trajectory: Trajectory
) -> tuple[np.ndarray, tuple | None, float]:
    """_settle_mode on the state y at t [s] with its crank angle as the phase (phi less offset [rad]: the guards read
    the angle as the solver steps it, turns_and_phase); returns the settled state (phi = offset + phase), mode and
    phase."""
    in_phase = np.array(y, dtype=float)
    in_phase[0] = phase
    settled, mode = _settle_mode(model, t, in_phase, mode, trajectory)
    phase = float(settled[0])
    if settled is not in_phase:  # a transition's state, the guard's own array: copied before phi is written
        settled = np.array(settled, dtype=float)
    settled[0] = offset + phase
    return settled, mode, phase


def _settle_mode(
    model: MachineModel, t: float, y: np.ndarray, mode, trajectory: Trajectory
) -> tuple[np.ndarray, tuple | None]:
    """Apply, at one instant, the transitions of guards that are already violated on entering a mode
    (a sleeve that comes to rest exactly where the forces pull it off, a stop reached as the motion
    reverses). More than MAX_INSTANT_EVENTS in a row means the governor's modes contradict each other."""
    for _ in range(MAX_INSTANT_EVENTS):
        violated = next((guard for guard in model.guards(mode, y) if guard.level(t, y) < -GUARD_TOLERANCE), None)
        if violated is None:
            return y, mode
        mode, y = violated.apply(t, y)
        _log_event(trajectory, t, violated.name, mode)
    _fail_stuck(trajectory, t)
    return y, mode


def _fail_stuck(trajectory: Trajectory, t: float) -> None:
    """End a run whose governor changes mode over and over at one instant."""
    trajectory.status = "failed"
    trajectory.message = (
        f"the governor changed mode {MAX_INSTANT_EVENTS} times at t = {t:.6g} s without moving "
        f"(last: {trajectory.events[-1][1]}); its friction, stops or limits contradict each other, "
        "or the sleeve is released exactly where the forces turn back (a grazing release)"
    )


def _log_event(trajectory: Trajectory, t: float, name: str, mode) -> None:
    trajectory.events.append((t, name))
    trajectory.modes.append((t, mode))
    trajectory.stats.events += 1


def turns_and_phase(phi: float, period: float) -> tuple[int, float]:
    """The crank angle phi [rad] as whole dynamic periods and the angle within one: (k, phi - k period) with
    k = floor(phi / period). The solvers carry the phase across their restarts and compare switch angles, table
    knots and windows with it, never with the growing phi, whose last place is 2e-9 rad at phi = 1e7 rad
    (docs/hard_cases.md, "Long runs"); only a segment's start reads the phase off phi."""
    turns = math.floor(phi / period)
    return turns, phi - turns * period


def fail_no_progress(model: MachineModel, trajectory: Trajectory, t: float, y, what: str) -> None:
    """End a run whose solver restarted MAX_RESTARTS_WITHOUT_PROGRESS times in a row at t [s] without the time
    advancing: status failed, with the time, the restart that repeats (what) and the state y; what was computed up to
    t stays."""
    trajectory.status = "failed"
    trajectory.message = (
        f"{model.scene.solver.method}: no progress at t = {t:.9g} s: {MAX_RESTARTS_WITHOUT_PROGRESS} "
        f"restarts in a row without the time advancing (the last at {what}; the state: "
        f"{state_text(model.state_names(), y)}); please report this scene"
    )


def state_text(names: tuple[str, ...], y) -> str:
    """A state for a message: 'phi = 1.2, omega = 3.4, ...'."""
    return ", ".join(f"{name} = {float(value):.6g}" for name, value in zip(names, y))


def fail_blown_up(model: MachineModel, trajectory: Trajectory, t: float, y, name: str, value: float) -> None:
    """End a run whose speed `name` (omega or omega_driven) is beyond MAX_SPEED, or not finite, at t [s] in the state
    y: status failed, with the time, the state and the likely cause; what was computed up to t stays."""
    trajectory.status = "failed"
    trajectory.message = blown_up_message(model, t, y, name, value)


def blown_up_message(model: MachineModel, t: float, y, name: str, value: float) -> str:
    """Why a run stopped at a speed beyond MAX_SPEED (limits.py): the time, the speed, the state and the likely
    cause, from the crank's net moment and inertia there."""
    solver = model.scene.solver
    cause = "a drive or load far too large for the machine's inertia (machine.inertia, machine.drive, machine.loads)"
    if name == "omega_driven":
        cause = (
            "moments far too large for the driven part's inertia, or a coupling too stiff for the method (its "
            "stiffness, damping; try Radau or BDF)"
        )
    else:
        try:
            state = np.array(y, dtype=float)
            J, moment = model.crank_side(t, state)
            cause = (
                f"the crank's net moment {moment:.3g} N m on J = {J:.3g} kg m^2 (an acceleration of "
                f"{moment / J:.3g} rad/s^2): {cause}"
            )
            state[1] *= 1.0 + 1e-6
            rate = -(model.crank_side(t, state)[1] - moment) / (J * 1e-6 * float(y[1]))  # -d epsilon/d omega [1/s]
            if solver.method == "RK4" and solver.step * rate > 2.785:  # outside RK4's region on the real axis
                cause = (
                    f"an RK4 step too long to be stable: solver.step = {solver.step:g} s against the crank "
                    f"speed's time constant J / |dM/domega| = {1.0 / rate:.3g} s (RK4 is stable below 2.79 of them); "
                    "expected a smaller solver.step"
                )
        except (ArithmeticError, ValueError, IndexError, TypeError):
            pass
    if solver.method == "RK4" and "RK4 step" not in cause:
        cause += f", or an RK4 step too long to be stable (solver.step = {solver.step:g} s)"
    return (
        f"{solver.method}: the run blew up at t = {t:.6g} s: {name} = {value:.6g} rad/s is beyond "
        f"{MAX_SPEED:g} rad/s, the limit on any machine's speed (the state: {state_text(model.state_names(), y)}); "
        f"likely cause: {cause}"
    )


def fail_too_many_steps(model: MachineModel, trajectory: Trajectory, t: float, y) -> None:
    """End a run that has taken MAX_STEPS steps (limits.py) at t [s] in the state y: status failed, with why."""
    trajectory.status = "failed"
    trajectory.message = (
        f"{model.scene.solver.method}: stopped at t = {t:.6g} s of {model.scene.scenario.duration:g} "
        f"s after {trajectory.stats.steps} steps, the limit of {MAX_STEPS:g} steps for one run (the "
        f"state: {state_text(model.state_names(), y)}); likely cause: a stiff machine for an "
        "explicit method (try Radau or BDF), tolerances tighter than needed (solver.rtol, "
        "solver.atol) or a motion that runs away"
    )


class _Shifted:
    """A solver's dense output with the wrapped-off whole periods added back to the angle and the mode's
    constraint (model.constraint: a stuck clutch's equal speeds) imposed, when it has one."""

    def __init__(self, dense, offset: float, constraint=None):
        self.dense, self.offset, self.constraint = dense, offset, constraint

    def __call__(self, t):
        y = self.dense(t)
        y[0] += self.offset
        if self.constraint is not None:
            self.constraint(y)
        return y

    def phase(self, t: float) -> float:
        """The crank angle alone at one time t [s] [rad], self(t)[0] to the bit (no constraint touches it): of a
        DOP853 step, its interpolant's sum for phi alone in the order scipy's Dop853DenseOutput sums it, without
        the arrays of the whole state a scalar call builds (Brent's method calls it about 8 times a switch)."""
        dense = self.dense
        if type(dense) is not Dop853DenseOutput:
            return self(t)[0]
        x = (t - dense.t_old) / dense.h
        value = 0.0
        for i, f in enumerate(reversed(dense.F)):
            value += f[0]
            value *= x if i % 2 == 0 else 1 - x
        return value + dense.y_old[0] + self.offset


def switch_window(grid: np.ndarray, period: float, phi: float, forward: bool) -> tuple[float, float]:
    """The interval (lo, hi) [rad] between consecutive switch angles of the grid (one period, sorted array) that the
    motion from phi (in [0, period)) is in, in phi's coordinates: on a switch angle, the one ahead in the direction of
    motion. Plain Python that numba compiles as it is (the compiled stepper's own restarts: integrators.py)."""
    tolerance = 1e-9 * period
    shift = 0.0
    if phi > period - tolerance:  # a whole period that floor() left unwrapped by round-off: the window beyond it
        phi, shift = phi - period, period
    if forward:
        i = np.searchsorted(grid, phi + tolerance, side="right") - 1
    else:
        i = np.searchsorted(grid, phi - tolerance, side="left") - 1
    lo = grid[i] if i >= 0 else grid[-1] - period
    hi = grid[i + 1] if i + 1 < grid.size else grid[0] + period
    return float(lo + shift), float(hi + shift)


def _switch_counts(phi: float, switches) -> list[int]:
    """For each switch (a row (angle, period) [rad] of switches, or a pair), how many of its angles (angle + k period)
    lie at or below phi [rad]."""
    return _switch_counts_at(np.array([phi]), switches)[0]


def _switch_counts_at(phis: np.ndarray, switches) -> list[list[int]]:
    """_switch_counts at each of the angles phis [rad], at once: floor((phi - angle) / period), one list per phi."""
    table = np.asarray(switches, dtype=float).reshape(-1, 2)
    return np.floor((phis[:, None] - table[:, 0]) / table[:, 1]).astype(np.int64).tolist()


def _first_event(
    dense,
    t_old: float,
    t_new: float,
    counts_old: list[int],
    switches,
    guards: list,
    interpolant_noise: np.ndarray | None = None,
    wrapped=None,
) -> tuple | None:
    """The earliest event in (t_old, t_new]: phi reaching a switch angle or a governor guard turning negative.

    Returns (time, state, switch counts after it, the guard or None for a switch, what happened, the crank's phase
    there), or None if the step has no event. switches: (angle, period) [rad] per switch (rows of an array, or
    pairs). wrapped: the same dense output in the phase, phi less whole periods
    (dense by default); the guards read it and the switches are crossings of the phase, their counts the phase's, so
    that a switch angle is compared with a number that keeps its precision however far the crank has turned
    (turns_and_phase). Switch angles: the step is probed at interior points so a crossing and its
    undoing within one step is not missed, and a crossing is located by Brent's method on the dense output. Switch
    counts are carried, not recomputed from phi, so a restart exactly on a switch angle is never taken for a new
    crossing. Guards: _guard_crossing, from the guard's polynomial along the whole step, finds a dip below the level
    and back however short. A guard that starts the step at its boundary (|value| <= GUARD_TOLERANCE, as a
    transition leaves it: the sleeve just released, just at rest) is crossed only when it falls below
    -GUARD_TOLERANCE: a release where the forces turn straight back (grazing) keeps its mode instead of switching
    back and forth at one instant, and a real release is located after the step's start. interpolant_noise (Radau
    only: atol + rtol |y| per state): Radau's dense output is its collocation polynomial, of order 3 inside the step
    (5 at the step's end) and not tangent to the motion at the step's start, so a sleeve released at a stop with
    almost no force dips back into it by up to about atol at the start of every step; a guard that starts the step at
    its boundary is then crossed only below minus its change over that noise (_release_level), or every restart
    would log another touch (thousands per contact).
    """
    first_guard = None
    wrapped = dense if wrapped is None else wrapped
    if guards:
        node_times = t_old + GUARD_NODE_FRACTIONS * (t_new - t_old)
        node_states = wrapped(node_times)
        for guard in guards:
            samples = np.array([guard.level(tau, node_states[:, k]) for k, tau in enumerate(node_times)])
            level = 0.0
            if samples[0] <= GUARD_TOLERANCE:
                level = -_release_level(guard, t_old, node_states[:, 0], interpolant_noise)
            t_cross = _guard_crossing(lambda tau: guard.level(tau, wrapped(tau)) - level, t_old, t_new, samples - level)
            if t_cross is not None and (first_guard is None or t_cross < first_guard[0]):
                first_guard = (t_cross, guard)
    if len(switches):
        probe_times = np.linspace(t_old, t_new, PROBES_PER_STEP + 2)
        phis = wrapped(probe_times)[0]
        probe_counts = _switch_counts_at(phis[1:], switches)  # at every probe after the start, at once
        previous = counts_old
        for i in range(1, probe_times.size):
            if first_guard is not None and probe_times[i - 1] >= first_guard[0]:
                break
            current = probe_counts[i - 1]
            forward = phis[i] > phis[i - 1]
            earliest = None
            for j in [j for j in range(len(switches)) if current[j] != previous[j]] if current != previous else []:
                angle, period = switches[j]
                boundary = angle + period * (previous[j] + 1 if forward else previous[j])
                t_cross = _root(lambda tau: _phase_at(wrapped, tau) - boundary, probe_times[i - 1], probe_times[i])
                if earliest is None or t_cross < earliest[0]:
                    earliest = (t_cross, j, boundary)
            if earliest is not None and (first_guard is None or earliest[0] < first_guard[0]):
                t_cross, j, boundary = earliest
                y = dense(t_cross)
                after = list(previous)
                after[j] += 1 if forward else -1
                y[0] += boundary - _phase_at(wrapped, t_cross)  # the whole periods (dense's) on the switch angle
                return t_cross, y, after, None, "switch", boundary
            previous = current
    if first_guard is None:
        return None
    t_cross, guard = first_guard
    y, phase = dense(t_cross), wrapped(t_cross)[0]
    return t_cross, y, _switch_counts(phase, switches) if len(switches) else counts_old, guard, guard.name, phase


def _phase_at(wrapped, t: float) -> float:
    """The crank angle [rad] of a dense output (a function of time [s] giving the state) at one time t: its phase
    (_Shifted.phase) or, for any other, the first entry of the state it gives."""
    return wrapped.phase(t) if isinstance(wrapped, _Shifted) else wrapped(t)[0]


def _release_level(guard, t: float, y: np.ndarray, noise: np.ndarray | None) -> float:
    """How far below 0 a guard that starts a step at its boundary must fall to be crossed [guard units]:
    GUARD_TOLERANCE, or with noise (per state) the larger sum_i |g(y + noise_i e_i) - g(y)|."""
    if noise is None:
        return GUARD_TOLERANCE
    value = guard.level(t, y)
    change = 0.0
    for i, delta in enumerate(noise):
        shifted = np.array(y, dtype=float)
        shifted[i] += delta
        change += abs(guard.level(t, shifted) - value)
    return max(GUARD_TOLERANCE, change)


def guard_polynomial(samples: np.ndarray) -> tuple[np.ndarray, float]:
    """A guard along one step as a polynomial in theta = (t - t_old) / h: from its values at the GUARD_NODES
    Chebyshev points theta_k = GUARD_NODE_FRACTIONS (both ends included) the coefficients c_0..c_8 of the
    interpolant, lowest power first, and a bound on how far the guard may be from it on [0, 1] [guard units]:
    twice the interpolant's last Chebyshev coefficient (zero when the guard is a polynomial of degree <= 7 in theta,
    as a guard linear in the state is along a dense output of DOP853, RK45, Radau, RK4) plus the round-off of the
    power basis, 1e-10 of the samples' spread."""
    spread = np.max(np.abs(samples - samples[0]))
    line = SAMPLES_TO_POWERS @ (samples - samples[0])
    line[0] += samples[0]
    return line, 2.0 * abs(LAST_CHEBYSHEV @ samples) + 1e-10 * spread


def monotone_ends(line: np.ndarray) -> np.ndarray:
    """The polynomial sum_j line[j] theta^j cut into pieces monotone on (0, 1]: the pieces' upper ends, sorted, 1
    last (the real parts of its derivative's roots inside (0, 1); complex roots only add harmless cuts)."""
    slope = line[1:] * np.arange(1.0, line.size)  # derivative, lowest power first
    roots = np.roots(slope[::-1].astype(np.complex128)).real  # complex: numba keeps the domain
    return np.sort(np.concatenate((roots[(roots > 0.0) & (roots < 1.0)], np.ones(1))))


def _guard_crossing(excess, t_old: float, t_new: float, samples: np.ndarray) -> float | None:
    """The time in (t_old, t_new] [s] where excess (a guard less its level, along the step's dense output) first
    falls below 0, or None. samples: excess at t_old + GUARD_NODE_FRACTIONS (t_new - t_old). The guard's polynomial
    (guard_polynomial: interpolant and error bound) is cut into monotone pieces; the first piece that ends within the
    bound of 0 is checked on the guard itself at that end and, when it is above 0 there, by minimising the guard on
    the pieces on both sides of it (Brent's bounded minimisation): a dip below 0 and back is found however short,
    and located by Brent's method between the last point known above 0 and the dip's bottom."""
    line, margin = guard_polynomial(samples)
    if line[0] - margin >= np.sum(np.abs(line[1:])):  # then the polynomial stays above the margin on [0, 1]
        return None
    h = t_new - t_old
    cuts = monotone_ends(line)
    lower = 0.0
    for i, upper in enumerate(cuts):
        if np.polynomial.polynomial.polyval(upper, line) < margin:
            t_low = t_old + upper * h
            low = excess(t_low)
            if low >= 0.0 and upper < 1.0:
                found = optimize.minimize_scalar(
                    excess,
                    bounds=(t_old + lower * h, t_old + cuts[i + 1] * h),
                    method="bounded",
                    options={"xatol": 1e-12 * h},
                )
                if found.fun < low:
                    t_low, low = float(found.x), float(found.fun)
            if low < 0.0:
                return _root(excess, t_old + lower * h, t_low)
        lower = upper
    return None


def _root(function, a: float, b: float) -> float:
    """Root of function in [a, b] by Brent's method; an end that is already on the root (round-off at a
    restart on the switch) is returned as it is."""
    fa, fb = function(a), function(b)
    if fa == 0.0 or fa * fb > 0.0:
        return a if abs(fa) <= abs(fb) else b
    return optimize.brentq(function, a, b, xtol=1e-15, rtol=4 * np.finfo(float).eps)
