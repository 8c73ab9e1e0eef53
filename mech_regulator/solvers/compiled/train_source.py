"""The drive train's and joint friction's part of the fast path's generated module (solvers/compiled/codegen.py):
the coupling and the driven part behind it, the friction clutch, the crank's Newton solve of joint friction with the
mechanism's kinetostatics, and their guards."""

from __future__ import annotations

from mech_regulator import mechanisms
from mech_regulator.effects import joint_friction, output_position_of
from mech_regulator.effects.definition import definition_of
from mech_regulator.mechanisms.linkage import flat_program, symbolic
from mech_regulator.model import MachineModel
from mech_regulator.model.drivetrain import DrivenModel
from mech_regulator.scene import machine_keys
from mech_regulator.solvers.compiled.source import (
    CLUTCH_MODE,
    CRANK_DIRECTION,
    DRIVEN_MODE,
    EXTERNAL_OFFSET,
    EXTERNAL_SLOPE,
    NORMAL_SLOTS,
    Parameters,
    effect_call,
    effect_definition,
    held_position_call,
    present,
    reads_position,
    reduced_lines,
)


def joint_friction_lines(
    model: MachineModel, p: Parameters, share: str, anchor: str, held: str, friction_slot: int | None
) -> list[str]:
    """Source that turns the crank's frictionless dydt[1] = epsilon_0 into the root of J epsilon = J epsilon_0 -
    sign(omega) F(epsilon) (MachineModel.rhs, effects.joint_friction): the force Q on the output link (the effects'
    output forces, the drive's times the throttle `share`), the joint reactions R0 + R1 epsilon of the mechanism's
    kinetostatics at (phi, omega, Q) and the Newton solve; a thrust collar alone needs no kinetostatics. anchor,
    held: the crank angle and slider position the tables in the output forces are read on (effect_call);
    friction_slot: CompiledScene's (the guides' normal signs and the joints' rate signs between two corners)."""
    friction = present(model.joint_friction, "model's joint friction")
    collar, tolerance = p.scalar(friction.collar), p.scalar(joint_friction.NEWTON_TOLERANCE)
    iterations = f"int({p.scalar(joint_friction.NEWTON_ITERATIONS)})"
    solve = p.formula(joint_friction.friction_acceleration)  # the reference path's own Newton solve, compiled
    if friction.loads is None:
        return [
            f"dydt[1] = {solve}(omega, J * dydt[1], J, {collar}, (0.0, 0.0, 0.0, 0.0), "
            f"(0.0, 0.0, 0.0, 0.0), (0j, 0j, 0j, 0j), (0j, 0j, 0j, 0j), False, {tolerance}, {iterations}, "
            "(0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0))"
        ]
    lines = ["force = 0.0"]
    scaled = []
    for effect in model.effects:
        if effect.output_force is None:
            continue
        definition = effect_definition(effect)
        call = effect_call(definition, p, "phi", "omega", "q", "dq", anchor, held, definition.output_force)
        if effect.role == "drive":
            scaled.append(f"force += {share} * {call}")
        else:
            lines.append(f"force += {call}")
    lines += scaled
    machine = model.scene.machine
    mechanism = machine.mechanism
    if mechanism is None:  # not present: mypy joins a union's members in its type variable
        raise TypeError("the fast path's code generator read the scene's mechanism, which is not there")
    joints = kinetostatics_joints(mechanism)
    core, structure, _ = mechanisms.linkage_of(mechanism)  # its generated kinetostatics, with gravity
    gravity = (machine.gravity[0], machine.gravity[1]) if machine.gravity is not None else None
    program = flat_program.encode(core, structure.groups, gravity)
    name, source = symbolic.joint_loads_source(program)
    p.functions[name] = source
    lines.append(f"R0, R1, ratios, _, _ = {name}(phi, omega, force, {p.table(program).rsplit(', ', 1)[0]})")
    arms = [0.0] * len(joints)  # a joint without friction: arm 0, its terms exact zeros
    for index, arm_length in zip(friction.indices, friction.arms):
        arms[index] = arm_length
    normals = ["0.0"] * len(joints)  # a guide's |N| read as s_N N (its p slot), every other joint's |R|
    first_sign = present(friction_slot, "friction slot")  # generate gives one to friction with loads
    for k, position in enumerate(friction.guides):
        normals[friction.indices[position]] = f"p[{first_sign + NORMAL_SLOTS * k}]"
    first_rate = first_sign + NORMAL_SLOTS * len(friction.guides)
    signs = "".join(f"p[{first_rate + j}], " for j in range(len(joints)))
    lines.append(
        f"dydt[1] = {solve}(omega, J * dydt[1], J, {collar}, "
        f"({''.join(p.scalar(v) + ', ' for v in arms)}), ratios, R0, R1, True, {tolerance}, {iterations}, "
        f"({signs}), ({''.join(sign + ', ' for sign in normals)}))"
    )
    return lines


def kinetostatics_joints(mechanism) -> tuple[str, ...]:
    """The joints a mechanism's kinetostatics reports, in its order (mechanisms.build_kinetostatics): its linkage's."""
    return tuple(joint.name for joint in mechanisms.linkage_of(mechanism)[0].joints)


def crank_guard_lines() -> list[str]:
    """Source of the joint friction's crank guard (MachineModel.guards), after the mode's: with s the sign of the
    crank's speed at the segment's start (p's CRANK_DIRECTION), 'crank stops', s omega, or, starting at rest (s = 0),
    'crank starts', -|omega| (omega leaves 0: the solver restarts to watch for the next stop)."""
    return [
        f"direction = p[{CRANK_DIRECTION}]",
        "levels[g] = direction * omega if direction != 0.0 else -abs(omega)",
        "g += 1",
    ]


def coupling_lines(
    model: MachineModel, p: Parameters, anchor: str, table_slots: tuple[int, ...]
) -> tuple[list[str], list[str]]:
    """Source of the coupling and the driven part behind it (MachineModel._train, drive_train_at): the crank's
    dydt[1] = (net - M_m) / J, d twist/dt = omega - omega2 and domega2/dt in the driven part's mode; and its guards
    (at rest: the holding margins R -+ push; turning: s omega2); anchor: 'p[slot]' of a coupling table's anchor, or
    NO_ANCHOR; table_slots: generate's (a driven part's table loads' anchors)."""
    coupling = present(model.coupling, "model's coupling")
    spec = present(model.scene.machine.coupling, "scene's coupling")
    driven_model = present(model.driven, "model's driven part")
    twist_index, speed_index = model.coupling_index, model.driven_speed_index
    if coupling.table is None:
        elastic = f"{p.scalar(present(coupling.stiffness, 'coupling stiffness'))} * twist"
    else:
        elastic = f"k.extrapolated_linear(twist, {anchor}, {p.table(coupling.table[0], coupling.table[1])})"
    driven = spec.driven
    state = [
        f"twist = y[{twist_index}]",
        f"omega2 = y[{speed_index}]",
        f"passed = {elastic} + {p.scalar(coupling.damping)} * (omega - omega2)",
    ]
    dynamics = ["phi2 = y[0] - twist"]
    if driven.mechanism is not None:
        dynamics += reduced_lines(
            driven.mechanism, model.scene.machine.gravity, p, "phi2", ("I_links", "dI", "weight2", "q2", "dq2")
        )
    else:
        dynamics.append("I_links, dI, weight2, q2, dq2 = 0.0, 0.0, 0.0, 0.0, 0.0")
    dynamics += [f"I2 = {p.scalar(coupling.driven.inertia)} + I_links", "smooth = 0.0"]
    located = {table.name: f"p[{slot}]" for table, slot in zip(model.state_tables, table_slots)}
    names = [f"driven part's {effect.name}" for effect in driven_model.effects[: len(driven.loads)]]
    anchors = {index: located[name] for index, name in enumerate(names) if name in located}
    dynamics += driven_smooth_lines(driven, p, "phi2", "omega2", "q2", "dq2", anchors, driven_model)
    resistance = f"{p.scalar(coupling.driven.resistance)} + (p[{EXTERNAL_OFFSET}] + p[{EXTERNAL_SLOPE}] * t)"
    rhs = (
        state
        + [
            "dydt[1] = (net - passed) / J",
            f"dydt[{twist_index}] = omega - omega2",
            f"if p[{DRIVEN_MODE}] == 2.0:",
            f"    dydt[{speed_index}] = 0.0",
            "else:",
        ]
        + [f"    {line}" for line in dynamics]
        + [
            f"    direction = 1.0 if p[{DRIVEN_MODE}] == 0.0 else -1.0",
            f"    dydt[{speed_index}] = k.driven_acceleration(direction, passed, weight2, smooth, dI, omega2, I2, "
            f"{resistance})",
        ]
    )
    guards = (
        [f"if p[{DRIVEN_MODE}] == 2.0:"]
        + [f"    {line}" for line in state + dynamics]
        + [
            f"    levels[g] = k.driven_margin(passed, weight2, smooth, dI, omega2, {resistance}, -1.0)",
            f"    levels[g + 1] = k.driven_margin(passed, weight2, smooth, dI, omega2, {resistance}, 1.0)",
            "    g += 2",
            f"elif p[{DRIVEN_MODE}] == 0.0:",
            f"    levels[g] = y[{speed_index}]",
            "    g += 1",
            "else:",
            f"    levels[g] = -y[{speed_index}]",
            "    g += 1",
        ]
    )
    return rhs, guards


def driven_smooth_lines(
    driven: machine_keys.DrivenPart,
    p: Parameters,
    phi: str,
    omega: str,
    q: str,
    dq: str,
    anchors: dict[int, str] | None = None,
    model: DrivenModel | None = None,
) -> list[str]:
    """Source adding a driven part's non-Coulomb moments to `smooth` (DrivenModel.smooth_moment): its own loads,
    then each branch's reduced to the main shaft, M_n(omega / i_1n) / i_1n (drivetrain._reduced); constant loads
    are Coulomb resistances, in R. anchors: per index of an own load that is a located table, the slot p[k] of its
    anchor phi2 [rad] (NaN: the table as it is); a slider table's is read on the piece of x held on the interval
    between its kinks around the anchor (`{q}_anchor<index>`, from model's effect and mechanism)."""
    anchors = anchors or {}
    lines = []
    for index, load in enumerate(driven.loads):
        slot = anchors.get(index)
        definition = definition_of(load)
        if definition.dry:
            continue
        if slot is None:
            lines.append(f"smooth += {effect_call(definition, p, phi, omega, q, dq)}")
        elif reads_position(definition):
            held = f"{q}_anchor{index}"
            located = present(model, "driven part's model")  # given with the anchors
            position = held_position_call(
                located.effects[index].kink_angles, output_position_of(located.reduced), p, slot
            )
            lines += [
                f"{held} = {position} if {slot} == {slot} else {q}",
                f"smooth += {effect_call(definition, p, phi, omega, q, dq, held=held)}",
            ]
        else:
            anchor = f"({slot} if {slot} == {slot} else {phi})"  # NaN: the table as it is
            lines.append(f"smooth += {effect_call(definition, p, phi, omega, q, dq, anchor=anchor)}")
    for branch in driven.branches:
        ratio = p.scalar(branch.ratio)
        definitions = [definition_of(load) for load in branch.loads]
        lines += [
            f"smooth += {effect_call(definition, p, phi, f'({omega} / {ratio})', q, dq)} / {ratio}"
            for definition in definitions
            if not definition.dry
        ]
    return lines


def clutch_lines(model: MachineModel, p: Parameters, crank: list[str]) -> tuple[list[str], list[str]]:
    """Source of the friction clutch and the driven part behind it (MachineModel._train, drivetrain.ClutchModel) in
    the train mode of p (CLUTCH_MODE, DRIVEN_MODE): dydt[1] and domega2/dt of clutch_forces, the driven part read at
    omega2 = omega while stuck. Stuck, domega2/dt is the crank's (the reference freezes omega2 and sets it to omega
    in its outputs, MachineModel.constraint; equal starting values and equal rates keep them equal bit for bit here).
    Guards, in drivetrain.train_guards' order: stuck, static_torque -+ T (crank: the crank's net moment F1, phi
    unclamped); slipping, s (omega - omega2); then the driven part's margins R -+ push at rest or s omega2 turning."""
    clutch = present(model.clutch, "model's clutch")
    index = model.driven_speed_index
    omega2 = f"omega2 = y[1] if p[{CLUTCH_MODE}] == 0.0 else y[{index}]"
    driven = ["smooth = 0.0"] + driven_smooth_lines(
        present(model.scene.machine.clutch, "scene's clutch").driven, p, "0.0", "omega2", "0.0", "0.0"
    )
    resistance = f"resistance = {p.scalar(clutch.driven.resistance)} + (p[{EXTERNAL_OFFSET}] + p[{EXTERNAL_SLOPE}] * t)"
    forces = (
        f"epsilon, epsilon2, torque, push = k.clutch_forces(p[{CLUTCH_MODE}], p[{DRIVEN_MODE}], net, J, smooth, "
        f"resistance, {p.scalar(clutch.driven.inertia)}, {p.scalar(clutch.kinetic_torque)})"
    )
    rhs = [omega2] + driven + [resistance, forces, "dydt[1] = epsilon", f"dydt[{index}] = epsilon2"]
    static = p.scalar(clutch.static_torque)
    guards = (
        crank
        + rhs[:-2]
        + [
            f"if p[{CLUTCH_MODE}] == 0.0:",
            f"    levels[g] = {static} - torque",
            f"    levels[g + 1] = {static} + torque",
            "    g += 2",
            "else:",
            f"    levels[g] = p[{CLUTCH_MODE}] * (omega - y[{index}])",
            "    g += 1",
            f"if p[{DRIVEN_MODE}] == 2.0:",
            "    levels[g] = resistance - push",
            "    levels[g + 1] = resistance + push",
            "    g += 2",
            f"elif p[{DRIVEN_MODE}] == 0.0:",
            f"    levels[g] = y[{index}]",
            "    g += 1",
            "else:",
            f"    levels[g] = -y[{index}]",
            "    g += 1",
        ]
    )
    return rhs, guards
