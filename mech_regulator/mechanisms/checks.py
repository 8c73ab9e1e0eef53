"""The checks of a scene that need its mechanisms' kinematics (docs/scenes.md, "Errors"): a preset four-bar or
walking beam whose crank turns fully, a linkage driven by its crank that assembles over the whole turn, an engine's
firing that fits its crankshaft, the determinate joint reactions joint friction needs. The scene's schema checks
everything else when a scene is read; these run when a scene becomes a machine (model.build_model) and where a
command analyses a mechanism without building one, and refuse it with the same kind of message."""

from __future__ import annotations

import math

from mech_regulator.errors import SceneError
from mech_regulator.mechanisms import walking_beam
from mech_regulator.mechanisms.engine import firing_delays
from mech_regulator.mechanisms.four_bar import unassemblable_crank_ranges
from mech_regulator.mechanisms.linkage import Dyad, assembly_failures, checked
from mech_regulator.mechanisms.linkage.cam import CamFollower, check_cams
from mech_regulator.mechanisms.linkage.kinetostatics import indeterminate
from mech_regulator.mechanisms.presets import linkage_core
from mech_regulator.scene import effect_keys, machine_keys, mechanism_keys, schema
from mech_regulator.scene.loading import problems_message

BRANCHED_GROUPS = ("RRR", "RRP", "RPR")  # the group types with two assemblies, chosen by a branch


def refuse_unbuildable(scene: schema.Scene, source: str | None = None) -> schema.Scene:
    """The scene, once mechanism_problems finds nothing in its machine; else SceneError listing every problem, from
    `source` (the scene's validation's words for where it came from; None: the scene's name)."""
    problems = mechanism_problems(scene.machine)
    if problems:
        raise SceneError(problems_message(source or f"scene '{scene.name}'", problems))
    return scene


def mechanism_problems(machine: machine_keys.Machine) -> list[str]:
    """'key: what is wrong; what is expected' for each problem of the machine's mechanisms (its own and its driven
    part's) and of what rests on their kinematics (an engine's firing, joint friction's reactions)."""
    parts = [("machine.mechanism", machine.mechanism)] + [
        (f"machine.{key}.driven.mechanism", part.driven.mechanism)
        for key, part in (("coupling", machine.coupling), ("clutch", machine.clutch))
        if part is not None
    ]
    problems = [
        f"{key}: {problem}"
        for key, mechanism in parts
        if mechanism is not None
        for problem in [_refusal(_check_mechanism, mechanism)]
        if problem is not None
    ]
    if problems:
        return problems
    for check in (_check_firing, _check_reactions):
        problem = _refusal(check, machine)
        if problem is not None:
            problems.append(f"machine: {problem}")
    return problems


def _refusal(check, subject) -> str | None:
    """What `check(subject)` refuses (its ValueError's message), or None."""
    try:
        check(subject)
    except ValueError as error:
        return str(error)
    except (ArithmeticError, RecursionError) as error:  # a check computing with extreme numbers
        return (
            f"its numbers cannot be computed with ({type(error).__name__}: {error}); expected values of a real machine"
        )
    return None


def _check_mechanism(mechanism: mechanism_keys.Mechanism) -> None:
    """Raise ValueError when the mechanism's crank cannot turn fully (or a linkage is not driven by it)."""
    if isinstance(mechanism, (mechanism_keys.FourBar, mechanism_keys.WalkingBeam)):
        _check_crank_turns(mechanism)
    if isinstance(mechanism, mechanism_keys.WalkingBeam):
        flattening = walking_beam.change_point(walking_beam.geometry_from_scene(mechanism))
        if flattening is not None:
            raise ValueError(
                f"{flattening}; expected a beam direction (or its opposite) outside the swing "
                "of both links, so that the parallelograms never fold"
            )
    if isinstance(mechanism, mechanism_keys.Linkage):
        _check_drivable(mechanism)


def _check_crank_turns(linkage: mechanism_keys.FourBar | mechanism_keys.WalkingBeam) -> None:
    """Raise ValueError naming the crank angles where the four-bar loop (crank, coupler, rocker, frame,
    frame_angle_deg) of a linkage cannot be assembled."""
    ranges = unassemblable_crank_ranges(
        linkage.crank, linkage.coupler, linkage.rocker, linkage.frame, math.radians(linkage.frame_angle_deg)
    )
    if ranges:
        spans = ", ".join(f"{math.degrees(lo):.2f} to {math.degrees(hi):.2f} deg" for lo, hi in ranges)
        raise ValueError(
            f"the four-bar (crank {linkage.crank}, coupler {linkage.coupler}, rocker {linkage.rocker}, frame "
            f"{linkage.frame} m) cannot be assembled for crank angles {spans}; the crank must turn fully: expected a "
            "Grashof crank (shortest link = crank, and shortest + longest < sum of the other two)"
        )


def _check_drivable(mechanism: mechanism_keys.Linkage) -> None:
    """Raise ValueError when the linkage is not driven by its crank through class-II groups (linkage.checked), its
    cams cannot be cut (linkage/cam.py check_cams: undercut, cam not the crank, ...), its branches name no group
    with two assemblies, or it does not assemble over the whole turn."""
    core = linkage_core(mechanism)
    structure = checked(core)
    check_cams(core, structure)
    internal = {
        group.internal.name for group in structure.groups if isinstance(group, Dyad) and group.kind in BRANCHED_GROUPS
    }
    internal |= {
        group.pair.name
        for group in structure.groups
        if isinstance(group, CamFollower) and group.guide.kind == "revolute"
    }  # an oscillating follower's side of the cam
    foreign = sorted(set(mechanism.branches) - internal)
    if foreign:
        raise ValueError(
            f"branches names {foreign}, which are not the internal joint of a group with two "
            f"assemblies ({', '.join(BRANCHED_GROUPS)}; PRP and RPP have one); expected some of "
            f"{sorted(internal)}"
        )
    failures = assembly_failures(core, structure)
    if failures:
        raise ValueError(
            "; ".join(failures) + "; expected a linkage whose crank turns fully (check the lengths and the branches)"
        )


def _check_firing(machine: machine_keys.Machine) -> None:
    """Raise ValueError when a multi-cylinder engine's firing does not fit its crankshaft (engine.firing_delays)."""
    mechanism, engine = machine.mechanism, machine.drive
    if (
        isinstance(mechanism, mechanism_keys.CrankSlider)
        and mechanism.cylinders
        and isinstance(engine, effect_keys.Engine)
    ):
        cylinders = mechanism.cylinders
        firing_delays(
            [c.throw_deg for c in cylinders],
            [c.bank_deg for c in cylinders],
            engine.cycle_deg,
            engine.firing_order,
            engine.firing_deg,
        )


def _check_reactions(machine: machine_keys.Machine) -> None:
    """Raise ValueError when joint friction is asked of a linkage whose joint reactions are indeterminate (a
    redundant link) or that has gear pairs (no mesh friction model)."""
    if machine.joint_friction is None or not isinstance(machine.mechanism, mechanism_keys.Linkage):
        return
    reason = indeterminate(checked(linkage_core(machine.mechanism)))
    gear_joints = [name for name, joint in machine.mechanism.joints.items() if joint.type == "gear"]
    if gear_joints:
        reason = f"the gear pairs {gear_joints} have no joint friction yet"
    if reason is not None:
        raise ValueError(
            f"joint_friction needs the joint reactions, but {reason}; expected no joint_friction on this "
            "linkage (only a thrust_collar)"
        )
