"""The follower jump (docs/theory.md §5.7, docs/linkages.md "Cams"): a cam pair holds only while the contact pushes.

The contact each cam must give along its follower's travel, Q_c(phi, omega, epsilon) (linkage/cam.py's
CamPair.contact_force), is checked on every solver step a run takes: at SAMPLES_PER_STEP + 1 points of each step,
its start and end included, epsilon the derivative at the point of the quadratic through three points of omega's dense
output inside that same step, STEP_FRACTION of the step apart (_accelerations). Every number depends on the step that
holds the point alone, so a stretch gives the same numbers however long it is and however it is read in chunks. A
monolithic run checks its steps as its trajectory grows (ContactWatch, CHECK_CHUNK_STEPS at a time, before a streamed
run hands them off); a co-simulation's exchange step checks its stretch once stepped (check_contact). Where Q_c first
turns negative the crossing is found (Brent's method on the dense output; at a step's start, where a jump began
that step, a load's or s'' at a switch angle, the start itself), the trajectory is cut there, an event `contact lost
at cam pair K` is recorded and the run ends `failed` with the time, crank angle and speed: beyond it the follower no
longer follows the cam, which the machine's reduction assumes.
"""

from __future__ import annotations

import bisect
import math

import numpy as np
from scipy import optimize

from mech_regulator.solvers.trajectory import Stream, Trajectory

SAMPLES_PER_STEP = 8  # intervals of each solver step whose ends are checked (its start and end among them)
STEP_FRACTION = 1e-3  # the spacing of epsilon's three points of omega, as a fraction of the step that holds them
# (docs/hard_cases.md §4: 4e-4 rad/s^2 off a fine run's on valve_gear, where a central difference a millionth of a
# 10 000-s stretch wide was 2.6e3 off)
RESOLVED_SPACINGS = 64  # epsilon's points are at least this many units in the last place of t apart (a step onto a
# switch can be shorter than the time's own resolution allows a fraction of it to be)
CHECK_CHUNK_STEPS = 2000  # solver steps a monolithic run's trajectory gains before ContactWatch checks them: well
# below analysis/stream.py's RETAINED_STEPS, so a streamed run hands off only steps already checked


KEPT_SCENES = 8  # the scenes with cams whose CamPairs are kept (built once per scene, not per stretch)
_PAIRS: dict[int, tuple] = {}  # id(scene) -> (scene, its CamPairs), the newest KEPT_SCENES


def _pairs(scene) -> tuple:
    """The CamPairs of a scene's machine mechanism (with its gravity; the scene checked their profiles), () without
    cam pairs."""
    mechanism = scene.machine.mechanism
    if getattr(mechanism, "type", None) != "linkage" or not any(
        joint.type == "cam" for joint in mechanism.joints.values()
    ):
        return ()
    if id(scene) not in _PAIRS:
        from mech_regulator.mechanisms import mechanism_geometry
        from mech_regulator.mechanisms.linkage.cam import CamFollower, CamPair

        core, structure = mechanism_geometry(mechanism)
        _PAIRS[id(scene)] = (
            scene,
            tuple(
                CamPair(core, group, scene.machine.gravity, check=False)
                for group in structure.groups
                if isinstance(group, CamFollower)
            ),
        )
        while len(_PAIRS) > KEPT_SCENES:
            del _PAIRS[next(iter(_PAIRS))]
    return _PAIRS[id(scene)][1]


class ContactLost(Exception):
    """Raised by ContactWatch from within a trajectory's add_piece once it has cut the trajectory where a cam's
    contact was lost (status failed, event and message recorded): the solver's loop ends there, nothing after it is
    computed."""


class ContactWatch:
    """What a monolithic run's trajectory calls after each piece it gains (Trajectory.stream): the cam contacts of its
    steps not checked yet are checked once CHECK_CHUNK_STEPS of them are held, then the trajectory goes on to `then`
    (a streamed run's digest, analysis/stream.py; None: nothing). A lost contact ends the run there (check_contact)
    and raises ContactLost. stream is what the trajectory is given: the watch, or `then` alone for a machine
    without cam pairs."""

    def __init__(self, model, then: Stream | None):
        self.pairs = _pairs(model.scene)
        self.then = then
        self.stream: Stream | None = self if self.pairs else then
        self.t_checked = -math.inf  # the end [s] of the steps checked
        self.steps_checked = 0  # of the run's steps, counting those a stream dropped

    def __call__(self, trajectory: Trajectory) -> None:
        """Check the steps gained since the last check once they are CHECK_CHUNK_STEPS, then hand on."""
        if trajectory.held_steps + trajectory.steps_dropped - self.steps_checked >= CHECK_CHUNK_STEPS:
            self.check(trajectory)
        if self.then is not None:
            self.then(trajectory)

    def check(self, trajectory: Trajectory) -> None:
        """Check the steps after the last check (all there are: at a load piece's end, the run's loop calls it); where
        a contact is lost, end the trajectory there (check_contact) and raise ContactLost."""
        if not self.pairs:
            return
        found = _first_loss(self.pairs, trajectory, self.t_checked)
        self.t_checked, self.steps_checked = trajectory.t_end, trajectory.held_steps + trajectory.steps_dropped
        if found is not None:
            _stop_at(trajectory, *found)
            raise ContactLost


def check_contact(model, trajectory: Trajectory, t_from: float, y: np.ndarray) -> np.ndarray:
    """Check the cam contacts of the model's machine over trajectory from t_from [s] (a step's start) to its end
    (module docstring): where one is lost, cut the trajectory there, record the event, set status failed with the
    message and return the state there; else return y (the state at the end) unchanged."""
    pairs = _pairs(model.scene)
    found = _first_loss(pairs, trajectory, t_from) if pairs else None
    return y if found is None else _stop_at(trajectory, *found)


def _first_loss(pairs: tuple, trajectory: Trajectory, t_from: float) -> tuple[float, object] | None:
    """(the first time [s] after t_from at which a cam pair's Q_c turns negative, that pair) over the steps of
    trajectory after t_from; None where every contact holds."""
    if trajectory.t_end <= t_from or not trajectory.interpolants:
        return None
    times, starts, ends = _check_points(trajectory, t_from)
    values = _contact_forces(pairs, trajectory, times, starts, ends)
    lost = np.flatnonzero(np.min(values, axis=0) < 0.0)
    if not lost.size:
        return None
    k = int(lost[0])
    pair = pairs[int(np.argmin(values[:, k]))]
    if times[k] == starts[k]:  # a step's start: negative from it on (a jump began the step: a load's, s'''s)
        return float(times[k]), pair
    within = starts[k : k + 1], ends[k : k + 1]  # times[k - 1] is in the same step: its start or an inner point
    t_lost = optimize.brentq(
        lambda t: float(_contact_forces((pair,), trajectory, np.array([t]), *within)[0, 0]),
        times[k - 1],
        times[k],
        xtol=1e-12 * max(1.0, times[k]),
    )
    return t_lost, pair


def _stop_at(trajectory: Trajectory, t_lost: float, pair) -> np.ndarray:
    """End the run at t_lost [s], where pair's contact is lost: cut the trajectory there, record the event, set status
    failed with the message; returns the state there."""
    state = trajectory(t_lost)
    trajectory.cut(t_lost)
    speed, _ = pair.jump()
    name = pair.group.pair.name
    trajectory.events.append((t_lost, f"contact lost at cam pair {name}"))
    trajectory.status = "failed"
    trajectory.message = (
        f"the follower {pair.group.follower} left its cam (cam pair {name}) at t = {t_lost:.6g} s, "
        f"crank angle {math.degrees(state[0]) % 360.0:.2f} deg, omega = {state[1]:.6g} rad/s: the "
        "contact force needed there turns negative (at steady speed this spring holds the follower "
        f"up to {speed:.6g} rad/s); the run stops there, as the follower no longer follows the cam"
    )
    return np.array(state, dtype=float)


def _check_points(trajectory: Trajectory, t_from: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(times [s], and the start and end [s] of the solver step each belongs to): SAMPLES_PER_STEP + 1 evenly spaced
    points, both ends included, on every step of the trajectory that ends after t_from."""
    first = max(bisect.bisect_right(trajectory.piece_edges, t_from) - 1, 0)  # the piece that holds t_from
    ends = np.concatenate(trajectory.step_ends[first:])
    starts = np.concatenate([[trajectory.piece_edges[first]], ends[:-1]])
    after = ends > t_from
    starts, ends = starts[after], ends[after]
    fractions = np.arange(SAMPLES_PER_STEP + 1) / SAMPLES_PER_STEP
    times = starts[:, None] + (ends - starts)[:, None] * fractions[None, :]
    times[:, -1] = ends  # the end itself, not start + length
    return times.ravel(), np.repeat(starts, fractions.size), np.repeat(ends, fractions.size)


def _contact_forces(
    pairs: tuple, trajectory: Trajectory, times: np.ndarray, starts: np.ndarray, ends: np.ndarray
) -> np.ndarray:
    """Q_c [N or N m] of each pair (rows) at times [s] (columns) in the solver steps [starts, ends] [s]."""
    state, epsilon = _accelerations(trajectory, times, starts, ends)
    return np.array([pair.contact_force(state[0], state[1], epsilon)[0] for pair in pairs])


def _accelerations(
    trajectory: Trajectory, times: np.ndarray, starts: np.ndarray, ends: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(the states at times [s], the crank's acceleration epsilon [rad/s^2] there): the derivative at each time of
    the quadratic through omega's dense output at three points of the step [start, end] that holds it, STEP_FRACTION
    of the step apart (at least RESOLVED_SPACINGS units in the time's last place) and centred on the time, shifted
    into the step near its ends. Newton's form on the three times as they are in floating point."""
    spacing = np.maximum(STEP_FRACTION * (ends - starts), RESOLVED_SPACINGS * np.spacing(np.abs(times)))
    centre = np.minimum(np.maximum(times, starts + spacing), ends - spacing)
    low, high = centre - spacing, centre + spacing
    states = trajectory(np.concatenate([times, low, centre, high]))
    omega_low, omega_centre, omega_high = states[1, times.size :].reshape(3, -1)
    slope_low = (omega_centre - omega_low) / (centre - low)
    curvature = ((omega_high - omega_centre) / (high - centre) - slope_low) / (high - low)
    return states[:, : times.size], slope_low + curvature * ((times - low) + (times - centre))
