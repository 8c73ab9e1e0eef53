"""The text of a machine and of its runs: what a scene computes (`describe`), the summary of a monolithic run
(`simulate`) and of a co-simulation (`simulate --exchange-step`, the nodes' `run`), a governed run's lines.

Light to import (the standard library only at module level): numpy, the model and the scene load inside the
functions that need them.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from mech_regulator.cli.report.outputs import wrote_lines
from mech_regulator.cli.report.terminal import terminal_text

if TYPE_CHECKING:
    from mech_regulator.model import MachineModel
    from mech_regulator.model.drivetrain import DrivenModel


def describe(model: MachineModel) -> str:
    """The effects, state vector, right-hand side and solver a scene uses."""
    from mech_regulator.solvers.advice import coupling_modes, stiffness_advice

    scene = model.scene
    machine = scene.machine
    lines = [f"scene: {scene.name}"]
    if scene.description:
        lines.append(f"  {scene.description.strip()}")
    units = {"phi": "rad", "omega": "rad/s", "twist": "rad", "omega_driven": "rad/s"}
    if model.governor is not None:  # its states' own (GovernorKind.state_units)
        units.update(zip(model.governor.state_names, model.governor.state_units))
    lines.append("state vector: " + ", ".join(f"{name} [{units[name]}]" for name in model.state_names()))
    if machine.mechanism is None:  # the model has a reduced(phi) exactly when the scene has a mechanism
        lines.append(f"inertia: constant J = {model.inertia_constant:g} kg m^2 (no mechanism: no dJ/dphi term)")
    else:
        lines.append(
            f"inertia: J(phi) = {model.inertia_constant:g} kg m^2 + {machine.mechanism.type} links "
            "(closed-form kinematics per step; J' omega^2 / 2 term included)"
        )
    lines.append("effects (each evaluated once per right-hand side):")
    for effect in model.effects:
        reads = ", ".join(sorted(effect.depends_on)) or "nothing"
        lines.append(f"  - {effect.role:<5} {effect.formula}   [reads {reads}]")
    if model.has_weight:
        from mech_regulator.model.building import has_cam_springs

        parts = (
            [f"weight of the links, g = {machine.gravity} m/s^2"] if machine.gravity and any(machine.gravity) else []
        )
        parts += ["the cam followers' springs"] if has_cam_springs(machine.mechanism) else []
        lines.append(f"  - load  {' and '.join(parts)}   [reads phi]")
    if model.load_pieces:
        changes = ", ".join(
            f"{p.start:g}-{p.end:g} s: {p.offset + p.slope * p.start:g}"
            + (f"->{p.offset + p.slope * p.end:g}" if p.slope else "")
            for p in model.load_pieces
        )
        lines.append(f"  - load  external load moment (N m) by time: {changes}   [reads t]")
    if not model.effects and not model.has_weight and not model.load_pieces:
        lines.append("  (none: the machine coasts)")
    if model.joint_friction is not None:
        lines.append(
            "joint friction (kinetostatics per right-hand side; epsilon solved from the implicit equation): "
            f"{model.joint_friction.formula}"
        )
    if model.coupling is not None:
        coupling = model.coupling
        modes = coupling_modes(model)
        assert modes is not None and machine.coupling is not None, "the model's coupling is the scene's"
        driven_mechanism = machine.coupling.driven.mechanism  # the driven part has a reduced(phi) exactly with it
        elastic = (
            f"{coupling.stiffness:g} twist"
            if coupling.table is None
            else f"M_elastic(twist) (table of {coupling.table[0].size} points, {coupling.table[0][0]:g} to "
            f"{coupling.table[0][-1]:g} rad, end slopes continued)"
        )
        driven = (
            f"I2 = {coupling.driven_inertia:g} kg m^2"
            if driven_mechanism is None
            else f"I2(phi_driven) = {coupling.driven_inertia:g} kg m^2 + {driven_mechanism.type} links"
        )
        lines.append(
            f"coupling: M_m = {elastic} + {coupling.damping:g} (omega - omega_driven) N m to a driven part of "
            f"{driven} (relative mode at the operating twist {modes.operating_twist:.4g} rad: stiffness "
            f"{modes.stiffness:.4g} N m/rad, natural frequency {modes.natural_frequency:.4g} rad/s, damping "
            f"ratio {modes.damping_ratio:.3g})"
        )
        lines += _driven_lines(model, coupling.driven)
    if model.clutch is not None:
        clutch = model.clutch
        lines.append(
            f"clutch: Coulomb friction, static {clutch.static_torque:g} N m, kinetic {clutch.kinetic_torque:g} "
            f"N m (exact stick/slip modes), to a driven part of I = {clutch.driven.inertia:g} kg m^2 "
            "reduced to its shaft"
        )
        lines += _driven_lines(model, clutch.driven)
    if model.governor is not None:
        lines.append(
            "governor (M_d = throttle * drive"
            + ("; hybrid modes with exact stick, break-away and stops):" if model.governor.hybrid else "):")
        )
        lines += [f"  {line}" for line in model.governor.describe()]
    lines.append(f"dynamic period: {math.degrees(model.dynamic_period()):g} deg of crank angle")
    if model.switch_angles():
        angles = ", ".join(f"{math.degrees(a):g}" for a, _ in model.switch_angles())
        lines.append(f"switch angles (moment jumps, located exactly by the adaptive solvers): {angles} deg")
    if model.breakpoints():
        lines.append(f"time breakpoints (no step crosses them): {', '.join(f'{t:g}' for t in model.breakpoints())} s")
    solver = scene.solver
    if solver.method == "RK4":
        detail = f"fixed step {solver.step:g} s"
    elif solver.method == "energy":
        detail = f"energy method, fixed step {solver.phi_step_deg:g} deg in phi"
    else:
        detail = f"adaptive, rtol {solver.rtol:g}, atol {solver.atol:g}"
    lines.append(f"solver: {solver.method} ({detail}); output at {solver.sample_rate:g} Hz")
    advice = stiffness_advice(model)
    if advice is not None:
        lines.append(f"note: {advice}")
    lines.append(
        f"scenario: {scene.scenario.duration:g} s from phi = {scene.scenario.initial.phi:g} rad, "
        f"omega = {scene.scenario.initial.omega:g} rad/s"
    )
    return terminal_text("\n".join(lines))


def _driven_lines(model: MachineModel, driven: DrivenModel) -> list[str]:
    """describe's lines for the driven part behind a coupling or clutch (`driven`, the model's): loads, branches,
    resistance at rest."""
    in_branches = {index for branch in driven.branches for index in branch.effects}
    lines = [
        f"  driven part's load: {effect.formula.replace('omega', 'omega_driven').replace('phi', 'phi_driven')}"
        for index, effect in enumerate(driven.effects)
        if index not in in_branches
    ]
    for branch in driven.branches:
        lines.append(
            f"  branch {branch.name}: I_n = {branch.inertia:g} kg m^2, i_1n = {branch.ratio:g} (adds "
            f"{branch.inertia / branch.ratio**2:.4g} kg m^2); section torque M_section_{branch.name} = "
            f"M_n,c + (I_n / i_1n) epsilon_driven"
        )
        lines += [f"    load {driven.effects[i].formula}" for i in branch.effects]
    lines.append(
        f"  at rest it is held by its Coulomb resistances (constant loads{' and the external load' if model.load_pieces else ''}"
        f"): {driven.resistance:g} N m{' + external' if model.load_pieces else ''}"
    )
    if model.load_pieces:
        lines.append("  the external load acts on the driven part")
    return lines


def format_summary(model: MachineModel, summary: dict) -> str:
    """The human-readable summary of a run."""
    lines = [
        f"scene {summary['scene']}: {summary['status']} at t = {summary['t_end']:.6g} s, "
        f"phi = {summary['phi_end']:.6g} rad, omega = {summary['omega_end']:.6g} rad/s"
    ]
    steady = summary["steady"]
    if steady is None:
        return terminal_text(lines[0] + "\nnothing was computed: " + summary["message"])
    last = steady["last_period"]
    if steady["steady"]:
        lines.append(
            f"steady motion from t = {steady['t_steady']:.4g} s "
            f"(dynamic period {math.degrees(steady['dynamic_period_rad']):g} deg)"
        )
    else:
        lines.append(f"not steady: {steady['note']}")
    if last is not None:
        lines.append(
            f"last dynamic period ({last['t_start']:.4g}-{last['t_end']:.4g} s): "
            f"omega_m = {last['omega_m']:.6g} rad/s ({last['omega_m'] * 30 / math.pi:.5g} rpm), "
            f"omega_max = {last['omega_max']:.6g}, omega_min = {last['omega_min']:.6g}, "
            f"delta = {last['delta']:.4g} (1/{1 / last['delta']:.4g})"
            if last["delta"] > 0
            else f"last dynamic period: omega = {last['omega_m']:.6g} rad/s, delta = 0"
        )
    energy = summary["energy"]
    works = ", ".join(f"{name} {value:.6g}" for name, value in energy["works"].items())
    lines.append(
        f"energy: works [J] {works or 'none'}; change of kinetic energy {energy['delta_kinetic']:.6g} J; "
        f"residual {energy['residual']:.3g} J ({energy['relative_residual']:.2g} relative)"
    )
    solver = summary["solver"]
    lines.append(
        f"solver {solver['method']} ({solver['path']} path): {solver['steps']} steps, {solver['nfev']} rhs evaluations"
        + (f", {solver['njev']} jacobians, {solver['nlu']} LU" if solver["njev"] else "")
        + (f", {solver['switches']} switches located" if solver["switches"] else "")
        + (f", {solver['restarts']} restarts" if solver["restarts"] else "")
        + (f", {solver['events']} mode events" if solver["events"] else "")
    )
    if summary.get("governor"):
        lines += governed_lines(summary["governor"])
    if summary.get("two_mass"):
        lines += two_mass_lines(summary["two_mass"])
    if summary.get("drive_train"):
        lines += _drive_train_lines(summary["drive_train"], energy["works"].get("clutch_slip"))
    return terminal_text("\n".join(lines + wrote_lines(summary)))


def _drive_train_lines(train: dict, slip_work: float | None) -> list[str]:
    """The drive train's part of a run summary: slip phases and lock times, held stretches, section torques."""
    lines = []
    clutch = train["clutch"]
    if clutch is not None:
        phases = (
            ", ".join(
                f"{start:.6g}-{end:.6g} s ({'motor ahead' if mode == 'slip+' else 'machine ahead'})"
                for start, end, mode in clutch["slip_phases"]
            )
            or "never"
        )
        locks = ", ".join(f"{t:.9g}" for t in clutch["lock_times"]) or "never"
        lines.append(
            f"clutch: slips {phases}; slip ends (locks) at {locks} s"
            + (f"; work lost in slip {-slip_work:.6g} J" if slip_work is not None else "")
        )
    if train["held"]:
        lines.append(
            "driven part held at rest by its resistances: "
            + ", ".join(f"{start:.6g}-{end:.6g} s" for start, end in train["held"])
        )
    if train["sections"]:
        if clutch is not None and clutch["beta"] is not None:
            lines.append(
                f"section torques (paper: M_kr = M_n,c + (I_n / i_1n) domega/dt; clutch reserve beta = "
                f"kinetic torque / nominal load {clutch['nominal_load']:.4g} N m = {clutch['beta']:.4g}):"
            )
        else:
            lines.append("section torques (M_kr = M_n,c + (I_n / i_1n) domega/dt):")
        for name, section in train["sections"].items():
            estimate = section["paper_estimate"]
            lines.append(
                f"  {name}: max {section['max']:.6g} N m at {section['time']:.4g} s (nominal "
                f"{section['nominal']:.4g} N m"
                + (f", paper's estimate {estimate:.6g} N m)" if estimate is not None else ")")
            )
    return lines


def format_cosimulation_summary(summary: dict) -> str:
    """The human-readable summary of a co-simulated run (command line or ROS nodes)."""
    lines = [
        f"scene {summary['scene']}: {summary['status']} at t = {summary['t_end']:.6g} s, omega = "
        f"{summary['omega_end']:.6g} rad/s; co-simulated with exchange step {summary['exchange_step']:g} s "
        f"({summary['samples']} exchanges)"
    ]
    steps = summary.get("exchange_steps")
    if summary.get("exchange_tolerance") is not None and steps and steps["count"]:
        lines.append(
            f"adaptive exchange step (tolerance {summary['exchange_tolerance']:g}): {steps['count']} steps of "
            f"{steps['min']:.4g} to {steps['max']:.4g} s, median {steps['median']:.4g} s"
        )
    if summary["message"]:
        lines.append(summary["message"])
    if summary["tripped_at"] is not None and summary["status"] != "tripped":  # a run that failed after its trip
        lines.append(f"overspeed trip at t = {summary['tripped_at']:.6g} s: throttle closed from then on")
    if "real_time_factor" in summary:  # the ROS nodes' pace, from the recorder
        lines.append(
            f"the nodes ran at {summary['real_time_factor']:.3g} x real time over the exchanges "
            f"({summary['wall_time_s']:.3g} s of wall time, start-up not included)"
        )
    if summary.get("governor"):
        lines += governed_lines(summary["governor"])
    return terminal_text("\n".join(lines + wrote_lines(summary)))


def two_mass_lines(periods: dict) -> list[str]:
    """The two-mass machine's part of a run summary: its periods (source 003) and largest coupling moment."""
    start, steady, peak = periods["start_up_end"], periods["steady_from"], periods["peak"]
    period_1 = (
        "the driven part never moves forward"
        if start is None
        else "none (the driven part moves at once)"
        if start == 0.0
        else f"0-{start:.6g} s (driven part at rest or rolling back)"
    )
    period_3 = f"from {steady:.6g} s" if steady is not None else "not reached"
    lines = [
        f"periods: 1 start-up {period_1}; 2 transient; 3 steady motion {period_3}",
        f"largest coupling moment M_m = {peak['moment']:.6g} N m at t = {peak['time']:.6g} s (period "
        f"{peak['period']})"
        + (
            f", {peak['ratio']:.4g} x the steady mean {peak['steady_mean']:.6g} N m"
            if peak["ratio"] is not None
            else ""
        ),
        f"twist from {periods['twist_min']:.6g} to {periods['twist_max']:.6g} rad",
    ]
    if periods["note"]:
        lines.append(f"note: {periods['note']}")
    return lines


def sleeve_text(point: dict) -> str:
    """'sleeve z mm, ' of an operating point, or nothing for a governor without a sleeve (PI: NaN, or None once the
    summary went through JSON)."""
    sleeve = point["sleeve"]
    return f"sleeve {sleeve * 1000:.4g} mm, " if sleeve is not None and sleeve == sleeve else ""


def governed_lines(governed: dict) -> list[str]:
    """The governor's part of a run summary: operating point and one line per load change."""
    point = governed["operating_point"]
    lines = [
        f"governor: predicted operating point at the initial load {point['external_load']:.4g} N m: "
        f"omega {point['speed']:.6g} rad/s, {sleeve_text(point)}throttle "
        f"{point['throttle']:.4g}" + (f" ({point['limited']})" if point["limited"] else "")
    ]
    for response in governed["load_responses"]:
        settling = (
            f"settles in {response['settling_time']:.3g} s"
            if response["settling_time"] is not None
            else "not settled by the end of the window"
        )
        lines.append(
            f"  load {response['load_before']:.4g} -> {response['load_after']:.4g} N m at {response['time']:.4g} s: "
            f"peak deviation {response['peak_deviation']:+.4g} rad/s after {response['peak_time']:.3g} s, {settling}, "
            f"overshoot {response['overshoot']:.3g} %, new speed {response['speed_after']:.6g} rad/s, static error "
            f"{response['static_error']:+.4g} rad/s (statics: {response['predicted_static_error']:+.4g})"
            + (f"; limits: {', '.join(response['limits'])}" if response["limits"] else "")
        )
    return lines
