"""The crank–slider machine of a scene as a MuJoCo multibody model with a closed kinematic loop.

Our model reduces the machine to its crank, `J(phi) omega' + 1/2 J'(phi) omega^2 = M_d + M_c`
(docs/theory.md §2.3); MuJoCo instead integrates the three bodies in their own coordinates and holds
the loop closed by a constraint force. It is the independent simulator of the speed benchmark:

- crank: a body on a hinge (z axis) at the origin, inertia J0 + J_flywheel ratio^2 about the axis (the
  crank's own inertia is in machine.inertia), its mass crank_mass at crank_cg along the crank for its weight;
- rod: a body on a hinge at the crank pin B = R (cos phi, sin phi), mass rod_mass at rod_cg from B along
  the rod, rod_inertia about its centre of mass;
- slider: a body on a slide joint along x on the line y = offset (the joint's value is the slider
  position x [m]), mass slider_mass;
- the loop: an equality `connect` pins the rod's far end to the slider. MuJoCo's constraints are soft: the
  violation is pulled back like a critically damped spring of time constant solref, and the impedance solimp
  (0.9999, MuJoCo's hardest) sets how much of the constraint force is applied at once. The time constant is
  CONSTRAINT_TIME_STEPS = 4 timesteps (2, MuJoCo's stiffest safe choice, was 2 to 5 times less accurate on
  crank_slider_bench; 8 and 16 worse again), with a tight Newton solver. The omega error still falls only
  about as dt^2 (not RK4's dt^4): the soft constraint, not the integrator, sets MuJoCo's accuracy;
- the drive and the loads as MuJoCo-native forces, so stepping needs no Python callback: a linear motor
  M = M0 (1 - omega / omega0) (or a constant moment) is a `general` actuator on the crank hinge with an affine
  bias M0 - (M0 / omega0) omega and no control; a constant load moment is another bias; the viscous load on
  the crank is the hinge's damping; slider_viscous is the slide joint's damping, slider_spring its stiffness
  with springref = free_position, slider_constant a constant bias on the slider; gravity is the model's.

Integrator RK4 at a fixed timestep; runs go through `mujoco.rollout` (native multi-step: one call steps the
whole run in C and returns every state), not a Python loop of mj_step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mech_regulator.mechanisms.crank_slider import slider_kinematics
from mech_regulator.scene import Scene, SceneError
from mech_regulator.scene.effect_keys import ConstantDrive, LinearMotor
from mech_regulator.scene.mechanism_keys import CrankSlider

NATIVE_DRIVES = ("constant", "linear_motor")
NATIVE_LOADS = ("constant", "viscous", "slider_constant", "slider_viscous", "slider_spring")
CONSTRAINT_IMPEDANCE = 0.9999  # solimp dmin = dmax: MuJoCo's largest (hardest) impedance
CONSTRAINT_TIME_STEPS = 4.0  # solref time constant in timesteps: of 2, 4, 8, 16 the most accurate on crank_slider_bench
SOLVER_TOLERANCE = 1e-12  # Newton solver's tolerance on the constraint forces [-]


def mujoco_refusal(scene: Scene) -> str | None:
    """Why a scene cannot run as the MuJoCo crank–slider (None if it can): it needs a single crank_slider
    driven by a constant moment or a linear motor, loads from NATIVE_LOADS, and no governor, coupling,
    clutch, joint friction or external load."""
    machine = scene.machine
    mechanism = machine.mechanism
    if mechanism is None or mechanism.type != "crank_slider" or mechanism.cylinders:
        return "the MuJoCo model is a single crank_slider (machine.mechanism.type: crank_slider, no cylinders)"
    if machine.drive is None or machine.drive.type not in NATIVE_DRIVES:
        found = machine.drive.type if machine.drive is not None else "none"
        return f"machine.drive type '{found}' has no MuJoCo-native form; expected one of {', '.join(NATIVE_DRIVES)}"
    for index, load in enumerate(machine.loads):
        if load.type not in NATIVE_LOADS:
            return (
                f"machine.loads[{index}] type '{load.type}' has no MuJoCo-native form; expected one of "
                f"{', '.join(NATIVE_LOADS)}"
            )
    for key in ("coupling", "clutch", "joint_friction"):
        if getattr(machine, key) is not None:
            return f"machine.{key} is set; the MuJoCo model is the crank–slider alone"
    if scene.governor is not None:
        return "the scene has a governor; the MuJoCo model has no governor"
    if scene.scenario.external_load != 0.0 or scene.scenario.load_events:
        return "the scene has an external load (scenario.external_load, load_events); the MuJoCo model has none"
    return None


def mujoco_parts(scene: Scene) -> tuple[CrankSlider, ConstantDrive | LinearMotor]:
    """The crank–slider and the native drive of a scene the MuJoCo model can express (mujoco_refusal); a SceneError
    naming the scene and the reason for any other."""
    refusal = mujoco_refusal(scene)
    if refusal is not None:
        raise SceneError(f"scene '{scene.name}': {refusal}")
    mechanism, drive = scene.machine.mechanism, scene.machine.drive
    assert isinstance(mechanism, CrankSlider) and isinstance(drive, ConstantDrive | LinearMotor), "mujoco_refusal"
    return mechanism, drive


def _affine_bias(scene: Scene, drive: ConstantDrive | LinearMotor) -> tuple[float, float, float, float]:
    """Constant and speed terms of the crank's moment (the drive's, less the constant loads) and the constant force
    on the slider as MuJoCo biases: (crank constant [N m], crank per omega [N m s/rad], crank damping [N m s/rad],
    slider constant [N])."""
    machine = scene.machine
    constant, per_speed = (
        (drive.torque, 0.0)
        if isinstance(drive, ConstantDrive)
        else (drive.stall_torque, -drive.stall_torque / drive.no_load_speed)
    )
    damping = slider_force = 0.0
    for load in machine.loads:
        if load.type == "constant":
            constant -= load.torque
        elif load.type == "viscous":
            damping += load.coefficient
        elif load.type == "slider_constant":
            slider_force += load.force
    return constant, per_speed, damping, slider_force


def crank_slider_mjcf(scene: Scene, timestep: float) -> str:
    """The MJCF text of the scene's crank–slider (see the module docstring) at a timestep [s]; the plane of the
    mechanism is MuJoCo's x-y plane and every hinge turns about z. A scene it cannot express is a SceneError."""
    link, drive = mujoco_parts(scene)
    machine = scene.machine
    R, l, e = link.crank, link.rod, link.offset
    J_crank = machine.inertia + (machine.flywheel.inertia * machine.flywheel.ratio**2 if machine.flywheel else 0.0)
    gx, gy = machine.gravity if machine.gravity is not None else (0.0, 0.0)
    # at the model's reference pose (every joint 0, so phi = 0) the rod runs from B = (R, 0) to C = (x_C, e)
    x_C, _dx, _ddx, theta_ref, _dtheta, _ddtheta = slider_kinematics(0.0, R, l, e)
    constant, per_speed, damping, slider_force = _affine_bias(scene, drive)
    spring = next((load for load in machine.loads if load.type == "slider_spring"), None)
    slider_damping = sum(load.coefficient for load in machine.loads if load.type == "slider_viscous")
    # a body needs a positive mass: a massless crank gets 1 kg on its axis (no moment, no inertia about z);
    # a massless rod or slider 1 ug (forces of order 1e-8 N against the solver's tolerance)
    crank_mass, crank_cg = (link.crank_mass, link.crank_cg) if link.crank_mass > 0.0 else (1.0, 0.0)
    crank_z = J_crank - crank_mass * crank_cg**2  # about its centre of mass, so J_crank about the axis
    if crank_z <= 0.0:
        raise SceneError(
            f"scene '{scene.name}': machine.inertia {machine.inertia:g} kg m^2 is less than the crank's "
            f"crank_mass crank_cg^2 = {crank_mass * crank_cg**2:g} kg m^2; MuJoCo needs the crank's "
            "inertia about its centre of mass to be positive"
        )
    rod_mass, slider_mass = max(link.rod_mass, 1e-9), max(link.slider_mass, 1e-9)
    rod_z = max(link.rod_inertia, 1e-12)

    def inertia(mass: float, z: float, x: float) -> str:
        # x, y principal moments equal to z: they satisfy the triangle inequality and never act (planar motion)
        return f'<inertial pos="{x!r} 0 0" mass="{mass!r}" diaginertia="{z!r} {z!r} {z!r}"/>'

    half_angle = 0.5 * theta_ref
    spring_attributes = (
        f' stiffness="{spring.stiffness!r}" springref="{spring.free_position!r}"' if spring is not None else ""
    )
    from mech_regulator.scene.limits import output_stem  # (a name with '"' or '<' would break the XML)

    return f"""<mujoco model="{output_stem(scene.name, "crank_slider")}">
  <compiler angle="radian"/>
  <option timestep="{timestep!r}" integrator="RK4" gravity="{gx!r} {gy!r} 0" solver="Newton"
          tolerance="{SOLVER_TOLERANCE!r}" iterations="100" ls_tolerance="1e-6">
    <flag contact="disable"/>
  </option>
  <worldbody>
    <body name="crank">
      <joint name="crank" type="hinge" axis="0 0 1" damping="{damping!r}"/>
      {inertia(crank_mass, crank_z, crank_cg)}
      <body name="rod" pos="{R!r} 0 0" quat="{math.cos(half_angle)!r} 0 0 {math.sin(half_angle)!r}">
        <joint name="rod" type="hinge" axis="0 0 1"/>
        {inertia(rod_mass, rod_z, link.rod_cg)}
      </body>
    </body>
    <body name="slider" pos="{x_C!r} {e!r} 0">
      <joint name="slider" type="slide" axis="1 0 0" ref="{x_C!r}" damping="{slider_damping!r}"{spring_attributes}/>
      {inertia(slider_mass, 1e-9, 0.0)}
    </body>
  </worldbody>
  <equality>
    <connect name="loop" body1="rod" body2="slider" anchor="{l!r} 0 0"
             solref="{CONSTRAINT_TIME_STEPS * timestep!r} 1" solimp="{CONSTRAINT_IMPEDANCE} {CONSTRAINT_IMPEDANCE} 0.001 0.5 2"/>
  </equality>
  <actuator>
    <general name="drive" joint="crank" gaintype="fixed" gainprm="0" biastype="affine"
             biasprm="{constant!r} 0 {per_speed!r}"/>
    <general name="slider_force" joint="slider" gaintype="fixed" gainprm="0" biastype="affine"
             biasprm="{slider_force!r} 0 0"/>
  </actuator>
</mujoco>
"""


@dataclass
class MujocoRun:
    """A MuJoCo run sampled after every step: times [s], crank angle phi [rad] and speed omega [rad/s],
    slider position x [m], the timestep [s] and the steps taken."""

    times: np.ndarray
    phi: np.ndarray
    omega: np.ndarray
    x_slider: np.ndarray
    timestep: float
    steps: int


class MujocoCrankSlider:
    """The scene's crank–slider compiled as a MuJoCo model at a timestep [s], ready to run from the scene's
    initial state (import of mujoco deferred to here: it is an optional dependency, extra `bench`)."""

    def __init__(self, scene: Scene, timestep: float):
        import mujoco
        from mujoco import rollout

        self.scene, self.timestep = scene, timestep
        self.crank_slider = mujoco_parts(scene)[0]
        self.model = mujoco.MjModel.from_xml_string(crank_slider_mjcf(scene, timestep))
        self.data = mujoco.MjData(self.model)
        self._rollout = rollout
        self._spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        self.data.qpos[:], self.data.qvel[:] = self.joint_state(
            scene.scenario.initial.phi, scene.scenario.initial.omega
        )
        mujoco.mj_forward(self.model, self.data)
        self.initial_state = np.empty(mujoco.mj_stateSize(self.model, self._spec))
        mujoco.mj_getState(self.model, self.data, self.initial_state, self._spec)

    def joint_state(self, phi: float, omega: float) -> tuple[np.ndarray, np.ndarray]:
        """Joint positions (crank angle phi, the rod's angle relative to the crank, slider x) and speeds of the
        closed loop at crank angle phi [rad] and speed omega [rad/s], from the closed-form kinematics:
        rod angle theta(phi) - phi - theta(0), its speed (theta' - 1) omega, slider x(phi) and x' omega."""
        link = self.crank_slider
        x, dx, _ddx, theta, dtheta, _ddtheta = slider_kinematics(phi, link.crank, link.rod, link.offset)
        theta_ref = slider_kinematics(0.0, link.crank, link.rod, link.offset)[3]
        return (np.array([phi, theta - phi - theta_ref, x]), np.array([omega, (dtheta - 1.0) * omega, dx * omega]))

    def run(self, duration: float) -> MujocoRun:
        """Step the model over duration [s] (rounded to whole steps) with one mujoco.rollout call."""
        steps = max(1, int(round(duration / self.timestep)))
        states, _sensors = self._rollout.rollout(self.model, self.data, self.initial_state, nstep=steps)
        states = states[0]
        nq = self.model.nq
        return MujocoRun(states[:, 0], states[:, 1], states[:, 1 + nq], states[:, 3], self.timestep, steps)


__all__ = [
    "MujocoCrankSlider",
    "MujocoRun",
    "NATIVE_DRIVES",
    "NATIVE_LOADS",
    "crank_slider_mjcf",
    "mujoco_parts",
    "mujoco_refusal",
]
