"""Kinematic analysis of a scene's mechanism over one turn of the crank at constant speed (source 004), and its
kinetostatics there (source 001).

With the crank turning at constant omega (epsilon = 0, phi = omega t), a point P(phi) of the mechanism has
velocity v = P'(phi) omega and acceleration a = P''(phi) omega^2, P' and P'' being the kinematic transfer
functions of `mechanisms.point_motions` (closed forms, no differentiation in time). The joint reactions and the
balancing moment on the crank at that motion (inertia forces and weights, nothing on the output) come from the
mechanism's kinetostatics (`mechanisms.build_kinetostatics`: group by group from the farthest inward for a linkage).
"""

from __future__ import annotations

import math

import numpy as np

from mech_regulator.mechanisms import point_motions
from mech_regulator.scene import mechanism_keys


def kinematics_table(mechanism: mechanism_keys.Mechanism, omega: float, count: int) -> dict[str, np.ndarray]:
    """Columns over one turn, at `count` crank angles phi = 2 pi k / (count - 1), k = 0..count-1 (both ends):
    phi [rad], t = phi / omega [s], and for every moving point P: P_x, P_y [m], P_vx, P_vy, P_v = |v| [m/s],
    P_ax, P_ay, P_a = |a| [m/s^2], with v = P' omega and a = P'' omega^2."""
    motions = point_motions(mechanism)
    phis = np.linspace(0.0, 2.0 * math.pi, count)
    samples = [motions(phi) for phi in phis]
    columns = {"phi": phis, "t": phis / omega}
    for name in samples[0]:
        position, first, second = (np.array([sample[name][k] for sample in samples]) for k in range(3))
        velocity, acceleration = first * omega, second * omega * omega
        columns.update(
            {
                f"{name}_x": position.real,
                f"{name}_y": position.imag,
                f"{name}_vx": velocity.real,
                f"{name}_vy": velocity.imag,
                f"{name}_v": np.abs(velocity),
                f"{name}_ax": acceleration.real,
                f"{name}_ay": acceleration.imag,
                f"{name}_a": np.abs(acceleration),
            }
        )
    return columns


def reactions_unavailable(mechanism: mechanism_keys.Mechanism) -> str | None:
    """Why the joint reactions of a mechanism are not computed, or None when they are: the walking beam preset and
    a multi-cylinder crank-slider have no kinetostatics (scene.machine_keys.NO_KINETOSTATICS), and a linkage with a
    redundant link is statically indeterminate (its reactions do not follow from equilibrium alone)."""
    if mechanism.type == "walking_beam" or getattr(mechanism, "cylinders", None) is not None:
        return f"the kinetostatics of a {mechanism.type} is not built here"
    if isinstance(mechanism, mechanism_keys.Linkage):
        from mech_regulator.mechanisms import mechanism_geometry
        from mech_regulator.mechanisms.linkage.kinetostatics import indeterminate

        return indeterminate(mechanism_geometry(mechanism)[1])
    return None


def reactions_table(
    mechanism: mechanism_keys.Mechanism, gravity: tuple[float, float] | None, omega: float, phis: np.ndarray
) -> dict[str, np.ndarray]:
    """Kinetostatics at constant crank speed omega [rad/s] (epsilon = 0) with the links' weights (gravity [m/s^2],
    None: weightless) and no load on the output, at the crank angles phis [rad]: R_<joint> = |R| [N], the magnitude of
    every joint's reaction (a guide's: its normal force), and M_balancing [N m], the moment on the crank that keeps
    its speed constant, M_b = 1/2 J'(phi) omega^2 - M_weight(phi). Empty where reactions_unavailable says why."""
    from mech_regulator.mechanisms import build_kinetostatics

    if reactions_unavailable(mechanism) is not None:
        return {}
    loads, joints = build_kinetostatics(mechanism, gravity)
    samples = [loads(float(phi), omega, 0.0) for phi in phis]
    columns = {
        f"R_{joint}": np.array([abs(sample.constant[index]) for sample in samples])
        for index, joint in enumerate(joints)
    }
    columns["M_balancing"] = np.array([sample.balancing[0] for sample in samples])
    return columns


def reactions_summary(columns: dict[str, np.ndarray]) -> dict[str, dict[str, float]]:
    """Per joint of a reactions_table: the largest reaction R_max [N] over the turn and the crank angle where it
    occurs [deg]; and for the balancing moment its least and largest values [N m] with their crank angles."""
    phi_deg = np.degrees(columns["phi"])
    summary = {
        key[2:]: {"R_max": float(columns[key].max()), "R_max_at_deg": float(phi_deg[columns[key].argmax()])}
        for key in columns
        if key.startswith("R_")
    }
    moment = columns["M_balancing"]
    summary["balancing_moment"] = {
        "min": float(moment.min()),
        "min_at_deg": float(phi_deg[moment.argmin()]),
        "max": float(moment.max()),
        "max_at_deg": float(phi_deg[moment.argmax()]),
    }
    return summary


def point_names(columns: dict[str, np.ndarray]) -> list[str]:
    """The moving points of a kinematics_table, in order."""
    return [key[:-2] for key in columns if key.endswith("_x")]


def kinematics_summary(columns: dict[str, np.ndarray]) -> dict[str, dict[str, float]]:
    """Per moving point: the box of its path (x_min, x_max, y_min, y_max [m]), the largest speed v_max [m/s]
    and acceleration a_max [m/s^2] over the turn and the crank angles where they occur [deg]."""
    phi_deg = np.degrees(columns["phi"])
    summary = {}
    for name in point_names(columns):
        x, y, v, a = (columns[f"{name}_{key}"] for key in ("x", "y", "v", "a"))
        summary[name] = {
            "x_min": float(x.min()),
            "x_max": float(x.max()),
            "y_min": float(y.min()),
            "y_max": float(y.max()),
            "v_max": float(v.max()),
            "v_max_at_deg": float(phi_deg[v.argmax()]),
            "a_max": float(a.max()),
            "a_max_at_deg": float(phi_deg[a.argmax()]),
        }
    return summary
