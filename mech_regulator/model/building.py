"""Assembling a validated scene into a MachineModel (model/machine.py): the effects the scene names, the external
load's pieces, the coupling, the joint friction, and the refusal of a machine whose reduced inertia J(phi) is not
positive over a turn (docs/theory.md §2.3)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy import optimize

from mech_regulator.effects import Effect, build_drive, build_load, output_position_of
from mech_regulator.effects.joint_friction import JointFrictionModel, build_joint_friction, worst_locking
from mech_regulator.governors import build_governor
from mech_regulator.mechanisms import build_reduced
from mech_regulator.mechanisms.checks import refuse_unbuildable
from mech_regulator.model.coupling import CouplingModel
from mech_regulator.model.drivetrain import ClutchModel, build_driven
from mech_regulator.model.machine import LoadPiece, MachineModel, Reduced
from mech_regulator.scene import SceneError
from mech_regulator.scene.schema import Scene


def _load_pieces(scene: Scene) -> tuple[LoadPiece, ...]:
    """Split the scenario's external load into pieces that are constant or linear in time."""
    scenario = scene.scenario
    if scenario.external_load == 0.0 and not scenario.load_events:
        return ()
    pieces: list[LoadPiece] = []
    now, value = 0.0, scenario.external_load
    for event in scenario.load_events:
        if event.time > now:
            pieces.append(LoadPiece(now, event.time, value, 0.0))
        if event.ramp > 0.0:
            slope = (event.torque - value) / event.ramp
            pieces.append(LoadPiece(event.time, event.time + event.ramp, value - slope * event.time, slope))
        now, value = event.time + event.ramp, event.torque
    if now < scenario.duration or not pieces:
        pieces.append(LoadPiece(now, scenario.duration, value, 0.0))
    return tuple(pieces)


def build_model(scene: Scene) -> MachineModel:
    """Assemble a validated scene into a MachineModel: only the effects the scene names are built; a scene whose
    mechanisms cannot be built is refused (SceneError, mechanisms/checks.py)."""
    machine = refuse_unbuildable(scene).machine
    flywheel = machine.flywheel.inertia * machine.flywheel.ratio**2 if machine.flywheel else 0.0
    gravity = (machine.gravity[0], machine.gravity[1]) if machine.gravity is not None else None
    has_weight = machine.mechanism is not None and (
        (gravity is not None and any(gravity) and _has_mass(machine.mechanism)) or has_cam_springs(machine.mechanism)
    )  # in M_weight too
    reduced = build_reduced(machine.mechanism, gravity if has_weight else None) if machine.mechanism else None
    _check_inertia(machine, machine.inertia + flywheel, reduced)
    kinematic_period = 2.0 * math.pi if machine.mechanism is not None else None
    effects = []
    if machine.drive is not None:
        effects.append(build_drive(machine.drive, machine.mechanism))
    effects += [build_load(load, kinematic_period, output_position_of(reduced)) for load in machine.loads]
    effects = _unique_names(effects)
    coupling = _coupling_model(machine, gravity)
    clutch = None
    if machine.clutch is not None:
        clutch = ClutchModel(
            machine.clutch.static_torque,
            machine.clutch.kinetic_torque,
            build_driven(machine.clutch.driven, _unique_names),
        )
    model = MachineModel(
        scene=scene,
        inertia_constant=machine.inertia + flywheel,
        reduced=reduced,
        has_weight=has_weight,
        effects=tuple(effects),
        load_pieces=_load_pieces(scene),
        coupling=coupling,
        clutch=clutch,
    )
    if machine.joint_friction is not None:
        model = dataclasses.replace(model, joint_friction=_joint_friction(model))
    if scene.governor is None:
        return model
    governor = build_governor(scene.governor, model.initial_balance_throttle)
    return dataclasses.replace(model, governor=governor)


def _coupling_model(machine, gravity: tuple[float, float] | None) -> CouplingModel | None:
    """The coupling and driven part of a scene's machine (None without machine.coupling); the driven
    mechanism's links weigh under the machine's gravity."""
    coupling = machine.coupling
    if coupling is None:
        return None
    mechanism = coupling.driven.mechanism
    if (
        mechanism is not None
        and mechanism.type == "linkage"
        and any(joint.type == "cam" for joint in mechanism.joints.values())
    ):
        raise SceneError(
            "machine.coupling.driven.mechanism has a cam pair: a cam behind a coupling is not supported "
            "yet (its contact is checked on the machine's own mechanism only); expected the cam on "
            "machine.mechanism"
        )
    weighs = mechanism is not None and gravity is not None and any(gravity) and _has_mass(mechanism)
    reduced = build_reduced(mechanism, gravity if weighs else None) if mechanism is not None else None
    driven = build_driven(coupling.driven, _unique_names, reduced, weighs)
    table = coupling.characteristic
    if table is None:
        return CouplingModel(coupling.stiffness, coupling.damping, driven)
    return CouplingModel(None, coupling.damping, driven, (np.array(table.twist), np.array(table.moment)))


def _joint_friction(model: MachineModel) -> JointFrictionModel:
    """The machine's joint friction; a self-locking machine (friction growing faster with epsilon than the
    inertia, effects.joint_friction) is refused with a SceneError."""
    friction = build_joint_friction(model.scene.machine)
    phi, ratio = worst_locking(friction, lambda angle: model.inertia(angle)[0])
    if ratio >= 1.0:
        raise SceneError(
            f"machine.joint_friction: the machine self-locks at phi = {math.degrees(phi):.1f} deg: there "
            f"the joint friction grows with the crank's acceleration {ratio:.3g} times as fast as the "
            "inertia resists it (sum rho_j |k_j| |dR_j/d epsilon| >= J), so the equation of motion has "
            "no unique acceleration; expected smaller joint radii or coefficient, or more inertia"
        )
    return friction


INERTIA_SCAN_POINTS = 720  # crank angles over a turn at which J(phi) is checked before its smallest value is refined


def _check_inertia(machine, J0: float, reduced: Reduced | None) -> None:
    """Refuse with a SceneError a machine whose reduced inertia J(phi) = J0 + J_links(phi) is not finite, or falls below
    MIN_INERTIA or below MIN_INERTIA_FRACTION of its largest value (limits.py) somewhere in a turn (a crank-slider
    with only a slider mass and no machine.inertia has J = 0 at the dead centres), or whose driven part's inertia is
    below MIN_INERTIA: there the acceleration M / J has no bound (or overflows) and the solvers grind to a halt. J is
    scanned at INERTIA_SCAN_POINTS angles and its smallest value refined by a bounded Brent search; the message
    names the keys and the mechanism's values."""
    from mech_regulator.scene.limits import MIN_INERTIA, MIN_INERTIA_FRACTION

    for key in ("coupling", "clutch"):
        part = getattr(machine, key)
        if part is not None and part.driven.inertia < MIN_INERTIA:
            raise SceneError(
                f"machine.{key}.driven.inertia = {part.driven.inertia:g} kg m^2: below the limit of "
                f"{MIN_INERTIA:g} kg m^2 for an inertia (moments divided by it would overflow)"
            )
    advice = "give machine.inertia > 0 (the rotor's, the crank's) or a flywheel"
    if reduced is None:
        if J0 < MIN_INERTIA:
            raise SceneError(
                f"machine.inertia = {machine.inertia:g} kg m^2 (with the flywheel's, J = {J0:g} kg m^2): "
                f"below the limit of {MIN_INERTIA:g} kg m^2 for an inertia (moments divided by it "
                "would overflow)"
            )
        return

    def inertia(phi: float) -> float:
        return J0 + reduced(phi)[0]

    phis = np.linspace(0.0, 2.0 * math.pi, INERTIA_SCAN_POINTS, endpoint=False)
    with np.errstate(all="ignore"):
        J = np.array([inertia(phi) for phi in phis], dtype=float)
    mechanism = machine.mechanism
    values = ", ".join(f"{key} {value:g}" for key, value in mechanism.model_dump().items() if isinstance(value, float))
    keys = (
        f"(J0 = machine.inertia + flywheel = {J0:g} kg m^2; machine.mechanism, type {mechanism.type}: {values}; "
        "lengths in m, masses in kg, inertias in kg m^2)"
    )
    if not np.all(np.isfinite(J)):
        where = math.degrees(phis[int(np.argmax(~np.isfinite(J)))])
        raise SceneError(
            f"machine: the reduced inertia J(phi) is not finite at phi = {where:.1f} deg {keys}; "
            "expected the lengths and masses of a real mechanism"
        )
    index, step = int(np.argmin(J)), phis[1] - phis[0]
    found = optimize.minimize_scalar(
        inertia, bounds=(phis[index] - step, phis[index] + step), method="bounded", options={"xatol": 1e-12}
    )
    J_min, phi_min = min((float(found.fun), float(found.x)), (float(J[index]), float(phis[index])))
    J_max = float(np.max(J))
    if J_min > MIN_INERTIA_FRACTION * J_max and J_min >= MIN_INERTIA:
        return
    limit = (
        f"above {MIN_INERTIA_FRACTION:g} of its largest value"
        if J_min <= MIN_INERTIA_FRACTION * J_max
        else f"at least {MIN_INERTIA:g} kg m^2 (the limit for an inertia)"
    )
    raise SceneError(
        f"machine: the reduced inertia J(phi) falls to {J_min:.3g} kg m^2 at phi = "
        f"{math.degrees(phi_min) % 360.0:.2f} deg (its largest: {J_max:.3g} kg m^2) {keys}; there the "
        f"crank's acceleration M / J has no bound: expected J(phi) {limit} over the whole turn: {advice}"
    )


def has_cam_springs(mechanism) -> bool:
    """Whether a linkage has a cam follower's spring (its moment is carried in the reduction's M_weight)."""
    return mechanism.type == "linkage" and any(
        joint.type == "cam" and joint.spring is not None for joint in mechanism.joints.values()
    )


def _has_mass(mechanism) -> bool:
    if mechanism.type == "linkage":  # a general linkage's masses are its links'
        return any(link.mass > 0 for link in mechanism.links.values())
    return any(getattr(mechanism, key) > 0 for key in type(mechanism).model_fields if key.endswith("_mass"))


def _unique_names(effects: list[Effect]) -> list[Effect]:
    """Rename repeated effect names to name_2, name_3, ... so output columns stay distinct."""
    seen: dict[str, int] = {}
    unique = []
    for effect in effects:
        seen[effect.name] = seen.get(effect.name, 0) + 1
        if seen[effect.name] > 1:
            effect = Effect(**{**effect.__dict__, "name": f"{effect.name}_{seen[effect.name]}"})
        unique.append(effect)
    return unique
