"""The follower jump (docs/theory.md §5.7, docs/linkages.md "Cams"): a cam pair holds only while the contact pushes.

After each stretch a solver integrated (a segment of the reference or the fast path, an exchange step of the nodes'
co-simulation) the contact each cam must give along its follower's travel, Q_c(phi, omega, epsilon)
(linkage/cam.py's CamPair.contact_force), is checked over the stretch: SAMPLES_PER_STEP points on each solver step,
epsilon by a central difference of the dense output. Where Q_c first turns negative the crossing is found (Brent's
method on the dense output), the trajectory is cut there, an event `contact lost at cam pair K` is recorded and the
run ends `failed` with the time, crank angle and speed: beyond it the follower no longer follows the cam, which the
machine's reduction assumes.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import optimize

from mech_regulator.solvers.trajectory import Trajectory

SAMPLES_PER_STEP = 8  # points on each solver step at which the contact is checked
DIFFERENCE_FRACTION = 1e-6  # the central difference's half-width, as a fraction of the stretch [-]


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


def has_cam_contacts(scene) -> bool:
    """Whether check_contact checks anything for the scene: its machine has cam pairs (it reads each stretch whole)."""
    return bool(_pairs(scene))


def check_contact(model, trajectory: Trajectory, t_from: float, y: np.ndarray) -> np.ndarray:
    """Check the cam contacts of the model's machine over trajectory from t_from [s] to its end (module docstring):
    where one is lost, cut the trajectory there, record the event, set status failed with the message and return
    the state there; else return y (the state at the end) unchanged."""
    pairs = _pairs(model.scene)
    if not pairs or trajectory.t_end <= t_from or not trajectory.interpolants:
        return y
    times = _check_times(trajectory, t_from)
    half = DIFFERENCE_FRACTION * (trajectory.t_end - t_from)

    def needed(t: np.ndarray, pair) -> np.ndarray:
        """Q_c of the cam pair at times t."""
        t = np.atleast_1d(t)
        low, high = np.clip(t - half, t_from, trajectory.t_end), np.clip(t + half, t_from, trajectory.t_end)
        state = trajectory(t)
        epsilon = (trajectory(high)[1] - trajectory(low)[1]) / (high - low)
        return pair.contact_force(state[0], state[1], epsilon)[0]

    values = np.array([needed(times, pair) for pair in pairs])
    lost = np.flatnonzero(np.min(values, axis=0) < 0.0)
    if not lost.size:
        return y
    k = int(lost[0])
    pair = pairs[int(np.argmin(values[:, k]))]
    t_lost = (
        times[0]
        if k == 0
        else optimize.brentq(
            lambda t: float(needed(np.array([t]), pair)[0]), times[k - 1], times[k], xtol=1e-12 * max(1.0, times[k])
        )
    )
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


def _check_times(trajectory: Trajectory, t_from: float) -> np.ndarray:
    """SAMPLES_PER_STEP points on every solver step of the trajectory after t_from, and t_from."""
    ends = np.concatenate([np.asarray(edges, dtype=float) for edges in trajectory.step_ends])
    ends = np.unique(np.concatenate([[t_from], ends[ends > t_from]]))
    fractions = np.arange(1, SAMPLES_PER_STEP + 1) / SAMPLES_PER_STEP
    inner = (ends[:-1, None] + np.diff(ends)[:, None] * fractions[None, :]).ravel()
    return np.concatenate([[t_from], inner])
