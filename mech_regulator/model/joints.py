"""What a machine's joint_states carries besides the crank, without ROS: the machine node's messages and the bags
(viz/bag.py) name the joints alike."""

from __future__ import annotations

import math

import numpy as np

MECHANISM_JOINTS = {
    "crank_slider": ("slider", "x_slider", "v_slider"),
    "four_bar": ("rocker", "theta4", "omega4"),
    "walking_beam": ("shuttle", "x_shuttle", "v_shuttle"),
}  # mechanism type -> (its output link's joint, the output columns of its position and velocity)


def output_joints(model, values: dict) -> list[tuple[str, float, float]]:
    """The joints joint_states carries besides the crank, as (joint name, position, velocity), from the machine's
    outputs `values` (MachineModel.columns, arrays, or joint_values at one state): the mechanism's output link
    (slider x [m], v [m/s]; rocker or shuttle), and a two-mass machine's coupling (twist [rad], its rate
    omega - omega_driven [rad/s]) and driven part (phi_driven [rad], NaN behind a clutch, which does not follow the
    driven part's angle; omega_driven [rad/s])."""
    joint = MECHANISM_JOINTS.get(model.scene.machine.mechanism.type if model.scene.machine.mechanism else "")
    joints = [(joint[0], values[joint[1]], values[joint[2]])] if joint is not None else []
    if model.coupling is not None:
        joints.append(("coupling", values["twist"], values["omega"] - values["omega_driven"]))
    if model.driven is not None:
        joints.append(("driven", values.get("phi_driven", math.nan), values["omega_driven"]))
    return joints


def joint_values(model, state: np.ndarray) -> dict[str, float]:
    """The outputs output_joints reads, at one state of `model` (its state vector's layout): the crank speed omega
    [rad/s], the mechanism's output position and velocity (piston 1's with several cylinders, as MachineModel.columns)
    from the reduced model at phi, a coupling's twist [rad] and phi_driven [rad], the driven part's omega_driven
    [rad/s]; the few values the machine node's joint_states needs, without the columns' other outputs."""
    phi, omega = float(state[0]), float(state[1])
    values = {"omega": omega}
    joint = MECHANISM_JOINTS.get(model.scene.machine.mechanism.type if model.scene.machine.mechanism else "")
    if joint is not None:
        *_, position, rate = model.reduced(phi)  # (J_links, dJ/dphi, the links' weight moment, q, dq/dphi)
        if not isinstance(position, float):  # several cylinders: one per piston
            position, rate = position[0], rate[0]
        values[joint[1]], values[joint[2]] = float(position), float(rate) * omega
    if model.coupling is not None:
        values["twist"] = float(state[model.coupling_index])
        values["phi_driven"] = phi - values["twist"]
    if model.driven is not None:
        values["omega_driven"] = float(state[model.driven_speed_index])
    return values
