"""Kinematic analysis of a scene's mechanism over one turn of the crank at constant speed (source 004).

With the crank turning at constant omega (epsilon = 0, phi = omega t), a point P(phi) of the mechanism has
velocity v = P'(phi) omega and acceleration a = P''(phi) omega^2, P' and P'' being the kinematic transfer
functions of `mechanisms.point_motions` (closed forms, no differentiation in time).
"""

from __future__ import annotations

import math

import numpy as np

from mech_regulator.mechanisms import point_motions
from mech_regulator.scene import schema


def kinematics_table(mechanism: schema.Mechanism, omega: float, count: int) -> dict[str, np.ndarray]:
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
        columns.update({f"{name}_x": position.real, f"{name}_y": position.imag,
                        f"{name}_vx": velocity.real, f"{name}_vy": velocity.imag, f"{name}_v": np.abs(velocity),
                        f"{name}_ax": acceleration.real, f"{name}_ay": acceleration.imag,
                        f"{name}_a": np.abs(acceleration)})
    return columns


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
        summary[name] = {"x_min": float(x.min()), "x_max": float(x.max()), "y_min": float(y.min()),
                         "y_max": float(y.max()), "v_max": float(v.max()), "v_max_at_deg": float(phi_deg[v.argmax()]),
                         "a_max": float(a.max()), "a_max_at_deg": float(phi_deg[a.argmax()])}
    return summary
