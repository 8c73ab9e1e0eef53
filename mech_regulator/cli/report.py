"""Text the command line prints: what a scene computes (`describe`) and the summary of a run."""

from __future__ import annotations

import math

from mech_regulator.model import MachineModel


def describe(model: MachineModel) -> str:
    """The effects, state vector, right-hand side and solver a scene uses."""
    scene = model.scene
    machine = scene.machine
    lines = [f"scene: {scene.name}"]
    if scene.description:
        lines.append(f"  {scene.description.strip()}")
    lines.append("state vector: phi [rad], omega [rad/s]")
    if model.reduced is None:
        lines.append(f"inertia: constant J = {model.inertia_constant:g} kg m^2 (no mechanism: no dJ/dphi term)")
    else:
        lines.append(f"inertia: J(phi) = {model.inertia_constant:g} kg m^2 + {machine.mechanism.type} links "
                     "(closed-form kinematics per step; J' omega^2 / 2 term included)")
    lines.append("effects (each evaluated once per right-hand side):")
    for effect in model.effects:
        reads = ", ".join(sorted(effect.depends_on)) or "nothing"
        lines.append(f"  - {effect.role:<5} {effect.formula}   [reads {reads}]")
    if model.has_weight:
        lines.append(f"  - load  weight of the links, g = {machine.gravity} m/s^2   [reads phi]")
    if model.load_pieces:
        changes = ", ".join(f"{p.start:g}-{p.end:g} s: {p.offset + p.slope * p.start:g}"
                            + (f"->{p.offset + p.slope * p.end:g}" if p.slope else "") for p in model.load_pieces)
        lines.append(f"  - load  external load moment (N m) by time: {changes}   [reads t]")
    if not model.effects and not model.has_weight and not model.load_pieces:
        lines.append("  (none: the machine coasts)")
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
    lines.append(f"scenario: {scene.scenario.duration:g} s from phi = {scene.scenario.initial.phi:g} rad, "
                 f"omega = {scene.scenario.initial.omega:g} rad/s")
    return "\n".join(lines)


def format_summary(model: MachineModel, summary: dict) -> str:
    """The human-readable summary of a run."""
    lines = [f"scene {summary['scene']}: {summary['status']} at t = {summary['t_end']:.6g} s, "
             f"phi = {summary['phi_end']:.6g} rad, omega = {summary['omega_end']:.6g} rad/s"]
    steady = summary["steady"]
    if steady is None:
        return lines[0] + "\nnothing was computed: " + summary["message"]
    last = steady["last_period"]
    if steady["steady"]:
        lines.append(f"steady motion from t = {steady['t_steady']:.4g} s "
                     f"(dynamic period {math.degrees(steady['dynamic_period_rad']):g} deg)")
    else:
        lines.append(f"not steady: {steady['note']}")
    if last is not None:
        lines.append(f"last dynamic period ({last['t_start']:.4g}-{last['t_end']:.4g} s): "
                     f"omega_m = {last['omega_m']:.6g} rad/s ({last['omega_m'] * 30 / math.pi:.5g} rpm), "
                     f"omega_max = {last['omega_max']:.6g}, omega_min = {last['omega_min']:.6g}, "
                     f"delta = {last['delta']:.4g} (1/{1 / last['delta']:.4g})" if last["delta"] > 0 else
                     f"last dynamic period: omega = {last['omega_m']:.6g} rad/s, delta = 0")
    energy = summary["energy"]
    works = ", ".join(f"{name} {value:.6g}" for name, value in energy["works"].items())
    lines.append(f"energy: works [J] {works or 'none'}; change of kinetic energy {energy['delta_kinetic']:.6g} J; "
                 f"residual {energy['residual']:.3g} J ({energy['relative_residual']:.2g} relative)")
    solver = summary["solver"]
    lines.append(f"solver {solver['method']}: {solver['steps']} steps, {solver['nfev']} rhs evaluations"
                 + (f", {solver['njev']} jacobians, {solver['nlu']} LU" if solver["njev"] else "")
                 + (f", {solver['switches']} switches located" if solver["switches"] else "")
                 + (f", {solver['restarts']} restarts" if solver["restarts"] else ""))
    for key in ("csv", "plot"):
        if key in summary:
            lines.append(f"wrote {summary[key]}")
    return "\n".join(lines)
