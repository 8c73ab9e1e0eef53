"""What a machine's joint_states carries besides the crank, without ROS: the machine node's messages and the bags
(viz/bag.py) name the joints alike."""

from __future__ import annotations

import math


def output_joints(model, values: dict) -> list[tuple[str, float, float]]:
    """The joints joint_states carries besides the crank, as (joint name, position, velocity), from the machine's
    outputs `values` (MachineStepper.outputs at one time, or MachineModel.columns: then arrays): the mechanism's
    output link (slider x [m], v [m/s]; rocker or shuttle), and a two-mass machine's coupling (twist [rad], its rate
    omega - omega_driven [rad/s]) and driven part (phi_driven [rad], NaN behind a clutch, which does not follow the
    driven part's angle; omega_driven [rad/s])."""
    kind = model.scene.machine.mechanism.type if model.scene.machine.mechanism else None
    columns = {
        "crank_slider": [("slider", "x_slider", "v_slider")],
        "four_bar": [("rocker", "theta4", "omega4")],
        "walking_beam": [("shuttle", "x_shuttle", "v_shuttle")],
    }.get(kind or "", [])
    joints = [(name, values[position], values[velocity]) for name, position, velocity in columns]
    if model.coupling is not None:
        joints.append(("coupling", values["twist"], values["omega"] - values["omega_driven"]))
    if model.driven is not None:
        joints.append(("driven", values.get("phi_driven", math.nan), values["omega_driven"]))
    return joints
