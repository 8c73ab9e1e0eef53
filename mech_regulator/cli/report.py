"""What the command line shows: what a scene computes (`describe`), the summary of a run and the answers of the
analysis commands (text or strict JSON), the progress of long work (a tqdm bar on a terminal, plain lines in a
log), and the output files (CSV, the check of their paths).

Light to import (the standard library only at module level): the ROS launcher and the command line's parser
import it; numpy, the model and the scene load inside the functions that need them.
"""

from __future__ import annotations

import json
import math
import os
import re
import stat
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

from mech_regulator.errors import EXIT_INACCURATE, EXIT_RUN_FAILED

if TYPE_CHECKING:
    from collections.abc import Iterable

    import numpy as np

    from mech_regulator.model import MachineModel
    from mech_regulator.model.drivetrain import DrivenModel


_UNSHOWABLE = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f\u061c\u200e\u200f\u2028\u2029\u202a-\u202e\u2066-\u2069]")
"""Characters a terminal would act on instead of showing: control characters but newline and tab (ESC starts an
escape sequence, BEL rings, CR returns to the line's start) and the bidirectional marks, embeddings, overrides and
isolates (U+200E, U+200F, U+061C, U+202A-U+202E, U+2066-U+2069: they reorder what follows them), and the line and
paragraph separators."""


def terminal_text(text: str) -> str:
    """Text from a scene (its name, a message quoting it) as the terminal may show it: each character of _UNSHOWABLE
    written as Python writes it in a string literal (ESC as \\x1b, U+202E as \\u202e), newlines and tabs kept."""
    return _UNSHOWABLE.sub(lambda match: repr(match.group())[1:-1], text)


def note(line: str) -> None:
    """A one-line note of a command on stderr (e.g. which path a run takes and why)."""
    print(f"mech-regulator: {terminal_text(line)}", file=sys.stderr)


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
        f"solver {solver['method']}: {solver['steps']} steps, {solver['nfev']} rhs evaluations"
        + (f", {solver['njev']} jacobians, {solver['nlu']} LU" if solver["njev"] else "")
        + (f", {solver['switches']} switches located" if solver["switches"] else "")
        + (f", {solver['restarts']} restarts" if solver["restarts"] else "")
        + (f", {solver['events']} mode events" if solver["events"] else "")
    )
    if summary.get("governor"):
        lines += _governed_lines(summary["governor"])
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
        lines += _governed_lines(summary["governor"])
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


def format_required_coupling(result, source: str) -> str:
    """The human-readable answer of the inverse problem (analysis.two_mass.RequiredCoupling)."""
    law = result.law
    lines = [
        f"scene {source}: coupling characteristic for the prescribed driven speed law",
        f"law: run-up from rest to omega_m = {law.omega_m:.6g} rad/s in T = {law.run_up:.6g} s, then omega_m + "
        f"A sin(k (t - T)) with A = {law.amplitude:.6g} rad/s, k = {law.frequency:.6g} rad/s "
        f"(delta = {2 * law.amplitude / law.omega_m:.4g})",
        f"tabulated over: {result.stretch} (from t = {result.t_from:.6g} s); "
        + ("realisable by an elastic coupling" if result.realisable else "NOT realisable by an elastic coupling"),
        f"one twist, moments apart by at most {result.loop_width:.3g} N m over it "
        f"({result.whole_loop_width:.3g} N m over the whole run); the driving speed fluctuates by "
        f"{result.driving_delta:.3g} of its mean",
    ]
    lines += [f"note: {note}" for note in result.notes]
    lines.append("characteristic (twist [rad] -> elastic moment [N m]; every point in --out):")
    step = max(1, result.table_twist.size // 12)
    picks = sorted(set(range(0, result.table_twist.size, step)) | {result.table_twist.size - 1})
    lines += [f"  {result.table_twist[i]:12.6g} {result.table_moment[i]:12.6g}" for i in picks]
    initial = result.initial
    lines.append(
        f"a forward run starts at t = {result.t_from:.6g} s of the law with phi = {initial['phi']:.6g} rad, "
        f"omega = {initial['omega']:.6g} rad/s, twist = {initial['twist']:.6g} rad (both parts at one speed)"
    )
    return terminal_text("\n".join(lines))


def _sleeve_text(point: dict) -> str:
    """'sleeve z mm, ' of an operating point, or nothing for a governor without a sleeve (PI: NaN, or None once the
    summary went through JSON)."""
    sleeve = point["sleeve"]
    return f"sleeve {sleeve * 1000:.4g} mm, " if sleeve is not None and sleeve == sleeve else ""


def _governed_lines(governed: dict) -> list[str]:
    """The governor's part of a run summary: operating point and one line per load change."""
    point = governed["operating_point"]
    lines = [
        f"governor: predicted operating point at the initial load {point['external_load']:.4g} N m: "
        f"omega {point['speed']:.6g} rad/s, {_sleeve_text(point)}throttle "
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


def format_governor(analysis: dict) -> str:
    """The human-readable statics and stability of a governed scene."""
    kind = analysis["kind"] + (f", {analysis['feedback']} feedback" if analysis["feedback"] else "")
    characteristic = analysis["characteristic"]
    lines = [
        f"scene {analysis['scene']}: {kind} governor" + (f", {analysis['sensor']} sensor" if analysis["sensor"] else "")
    ]
    if characteristic is None:  # PI
        lines.append(
            f"isochronous: omega = {analysis['set_speed']:.6g} rad/s (the set speed) at every load the "
            f"valve's travel can balance; statism (degree of non-uniformity) {analysis['statism']:.4g}"
        )
    else:
        speeds, sleeve = characteristic["speed"], characteristic["sleeve"]
        lines += [
            f"static characteristic: omega = {speeds[0]:.5g} rad/s at z = {sleeve[0] * 1000:.4g} mm to "
            f"{speeds[-1]:.5g} rad/s at z = {sleeve[-1] * 1000:.4g} mm; statism (degree of non-uniformity) "
            f"{analysis['statism']:.4g}",
            "insensitivity (sleeve friction) at the operating point: "
            f"{analysis['insensitivity_at_operating_point']:.4g}",
        ]
    if analysis["kind"] == "indirect":
        lines.append(f"set speed (sleeve at the pilot's neutral): {analysis['set_speed']:.6g} rad/s")
    lines.append("operating points (cycle-averaged machine):")
    for point in analysis["operating_points"]:
        servo = f", servo {point['servo']:.4g}" if point["servo"] == point["servo"] else ""
        lines.append(
            f"  load {point['external_load']:8.4g} N m: omega {point['speed']:.6g} rad/s "
            f"({point['speed'] * 30 / math.pi:.5g} rpm), {_sleeve_text(point)}"
            f"throttle {point['throttle']:.4g}{servo}" + (f"  [{point['limited']}]" if point["limited"] else "")
        )
    droop = analysis["droop"]
    lines.append(
        f"droop: {droop['per_unit_load']:+.4g} rad/s per N m of load"
        + (
            f"; load events leave {', '.join(f'{v:+.4g}' for v in droop['per_event'])} rad/s"
            if droop["per_event"]
            else ""
        )
    )
    linear = analysis["linear"]
    eigen = ", ".join(_complex(re, im) for re, im in linear["eigenvalues"])
    lines.append(
        f"linear stability of the averaged model ({', '.join(linear['state_names'])}): "
        f"{'stable' if linear['stable'] else 'UNSTABLE'}"
    )
    lines.append(f"  eigenvalues [1/s]: {eigen}")
    re, im = linear["dominant"]
    lines.append(
        f"  dominant mode {_complex(re, im)}: damping ratio {linear['damping_ratio']:.4g}, "
        + (f"period {linear['period']:.4g} s" if im else "not oscillating")
        + (f", amplitude x{math.exp(re * linear['period']):.3g} per period" if im else "")
    )
    if linear["vyshnegradsky"]:
        A, B = linear["vyshnegradsky"]
        lines.append(
            f"  Vyshnegradsky: A = {A:.4g}, B = {B:.4g}, A B = {A * B:.4g} "
            f"({'> 1: stable' if A * B > 1 else '<= 1: unstable'})"
        )
    if linear["pi_loop"]:
        a1, a0 = linear["pi_loop"]
        lines.append(
            f"  PI loop p^2 + a1 p + a0: a1 = {a1:.4g} 1/s, a0 = {a0:.4g} 1/s^2 "
            f"({'both > 0: stable' if a1 > 0 and a0 > 0 else 'not both > 0: unstable'})"
        )
    if linear["critical_damping"] is not None:
        lines.append(f"  sleeve damping at the stability boundary: {linear['critical_damping']:.5g} N s/m")
    floquet = analysis["floquet"]
    if floquet is not None:
        lines.append(
            f"periodic steady state (Floquet, orbit residual {floquet['residual']:.1g}): "
            f"{'stable' if floquet['stable'] else 'UNSTABLE'}, cycle {floquet['cycle_time'] * 1000:.4g} ms, "
            f"mean speed {floquet['mean_speed']:.6g} rad/s; it passes phi = 0 at omega = "
            f"{floquet['orbit'][0]:.6g} rad/s (start a run there to begin in steady state)"
        )
        lines.append("  multipliers |mu|: " + ", ".join(f"{math.hypot(*m):.5g}" for m in floquet["multipliers"]))
        lines.append(
            "  averaged model exp(lambda T): "
            + ", ".join(f"{math.hypot(*m):.5g}" for m in floquet["averaged_multipliers"])
        )
    return terminal_text("\n".join(lines + wrote_lines(analysis)))


def _complex(re: float, im: float) -> str:
    return f"{re:.4g}" if im == 0 else f"{re:.4g} {'+' if im > 0 else '-'} {abs(im):.4g}i"


def to_json(data) -> str:
    """Strict JSON (no NaN or Infinity, which jq and JavaScript reject): non-finite numbers become null."""
    import numpy as np

    def finite(value):
        if isinstance(value, dict):
            return {key: finite(item) for key, item in value.items()}
        if isinstance(value, (list, tuple)):
            return [finite(item) for item in value]
        if isinstance(value, (np.floating, np.integer)):
            value = value.item()
        if isinstance(value, float) and not math.isfinite(value):
            return None
        return value

    return json.dumps(finite(data), indent=2, allow_nan=False)


PROGRESS_INTERVAL_VARIABLE = "MECH_REGULATOR_PROGRESS_INTERVAL"
PROGRESS_INTERVAL = 3.0  # [s] of wall time between two progress lines in a log (not a terminal), by default
START_UP_SHOWN = 0.05  # [s] of wall time before the first update from which the final line names the start-up


def progress_bar(
    total: float | None,
    quiet: bool,
    label: str = "simulating",
    quantity: str | None = "t",
    unit: str = "s",
    started: float | None = None,
):
    """The progress of long work on stderr, as a context manager with tqdm's `update(amount)` and `n`: nothing
    when quiet; tqdm's bar on a terminal; in a log, a pipe or a notebook (stderr not a terminal, where tqdm would
    show nothing useful), a plain line every few seconds of wall time (ProgressLines). total: the amount to do,
    simulated seconds by default (None: unknown, a count); label names the work, quantity the amount
    ('t = 3.2 / 10 s'; None: '3.2 / 10 s'), unit its unit, started when the work was asked for (time.monotonic()
    [s]; None: now)."""
    label = terminal_text(label)
    if quiet or not _is_terminal(sys.stderr):
        return ProgressLines(total, label, quantity, unit, progress_interval(), enabled=not quiet, started=started)
    from tqdm import tqdm

    amount = f"{quantity} = " if quantity else ""
    if total is None:
        return tqdm(desc=label, file=sys.stderr, bar_format=f"{{desc}}: {{n:.4g}} {unit} [{{elapsed}}]")
    return tqdm(
        total=total,
        desc=label,
        file=sys.stderr,
        bar_format=f"{{l_bar}}{{bar}}| {amount}{{n:.3g}}/{{total:.3g}} {unit} [{{elapsed}}<{{remaining}}]",
    )


def progress_interval() -> float:
    """Wall time [s] between two progress lines in a log: $MECH_REGULATOR_PROGRESS_INTERVAL when it is a number
    >= 0, else PROGRESS_INTERVAL."""
    try:
        interval = float(os.environ.get(PROGRESS_INTERVAL_VARIABLE, ""))
    except ValueError:
        return PROGRESS_INTERVAL
    return interval if math.isfinite(interval) and interval >= 0.0 else PROGRESS_INTERVAL


def _is_terminal(stream) -> bool:
    try:
        return stream.isatty()
    except (AttributeError, ValueError):  # no isatty, or closed
        return False


class ProgressLines:
    """Progress as plain lines on stderr for a log: after `interval` s of wall time since the last line, the next
    update prints `simulating lathe: t = 3.2 / 10 s (32 %), 4.1 s elapsed, ETA 8.7 s`; at the end `simulating
    lathe: done: t = 10 / 10 s in 12.3 s` (`stopped at` when the work ended short of its total), with `; start-up
    3.1 s` when the work began that long after `started`. The times are the work's own: from its start (the
    last update that still reported nothing done: the nodes' first diagnostics come as their exchanges start; else
    the bar's creation) to the latest update, so that a start-up (the nodes' discovery) is neither in the ETA (the
    time so far scaled by what is left) nor in the duration, which is then the summary's (the nodes' wall time over
    the exchanges; the start-up from the command). Work that ends within one interval prints nothing. The same
    interface as the tqdm bar the command line uses (update, n, set_description_str, close, a context manager);
    silent unless enabled (--quiet). No thread: a line comes with an update."""

    def __init__(
        self,
        total: float | None,
        label: str,
        quantity: str | None,
        unit: str,
        interval: float,
        enabled: bool = True,
        file=None,
        clock=time.monotonic,
        started: float | None = None,
    ):
        self.total, self.label, self.quantity, self.unit = total, label, quantity, unit
        self.interval, self.enabled, self.file, self.clock = interval, enabled, file, clock
        self.n = 0.0
        self.stage = ""
        self.start = self.last = self.began = self.latest = clock()  # began: the work's start; latest: its update
        self.started = self.start if started is None else started  # when the work was asked for
        self.printed = False
        self.closed = False

    def __enter__(self) -> ProgressLines:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def update(self, amount: float = 1) -> None:
        now = self.latest = self.clock()
        self.n += amount
        if self.n == 0.0:
            self.began = now  # nothing done yet: the work has not begun
        if self.enabled and now - self.last >= self.interval:
            self.last = now
            elapsed = now - self.began
            self._print(
                f"{self._label()}: {self._amount()}{self._share()}, {_duration(elapsed)} elapsed" + self._eta(elapsed)
            )

    def set_description_str(self, text: str, refresh: bool = False) -> None:
        """The current stage of the work (flywheel: the flywheel being simulated), shown after the label."""
        self.stage = text

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        if self.enabled and (self.printed or self.clock() - self.start >= self.interval):
            short = self.total is not None and self.n < self.total * (1.0 - 1e-9)
            start_up = self.began - self.started
            self._print(
                f"{self.label}: {'stopped at' if short else 'done:'} {self._amount()} "
                f"{'after' if short else 'in'} {_duration(self.latest - self.began)}"
                + (f"; start-up {_duration(start_up)}" if start_up >= START_UP_SHOWN else "")
            )

    def _label(self) -> str:
        return f"{self.label} ({self.stage})" if self.stage else self.label

    def _amount(self) -> str:
        amount = f"{self.quantity} = " if self.quantity else ""
        if self.total is None:
            return f"{amount}{self.n:.4g} {self.unit}"
        return f"{amount}{_progress_number(self.n)} / {_progress_number(self.total)} {self.unit}"

    def _share(self) -> str:
        return f" ({100.0 * self.n / self.total:.0f} %)" if self.total else ""

    def _eta(self, elapsed: float) -> str:
        """', ETA ...' at the pace of the work so far ('' without a total)."""
        if not self.total:
            return ""
        if self.n <= 0.0:
            return ", ETA unknown"
        return f", ETA {_duration(max(elapsed * (self.total - self.n) / self.n, 0.0))}"

    def _print(self, line: str) -> None:
        self.printed = True
        print(line, file=self.file or sys.stderr, flush=True)


def _progress_number(value: float) -> str:
    """An amount for a progress line: 3 significant digits, and every digit of its integer part ('42.7', '3600',
    '12346' rather than '3.6e+03' and '1.23e+04'), so that a long run's lines tell its pace to the second."""
    return f"{value:.{max(3, len(f'{abs(value):.0f}'))}g}"


def _duration(seconds: float) -> str:
    """Wall time for a progress line: '4.1 s', '2 min 05 s', '1 h 02 min'."""
    if seconds < 99.95:
        return f"{seconds:.1f} s"
    minutes, rest = divmod(round(seconds), 60)
    if minutes < 60:
        return f"{minutes} min {rest:02d} s"
    return f"{minutes // 60} h {minutes % 60:02d} min"


def write_csv(path, columns: dict[str, np.ndarray] | Iterable[dict[str, np.ndarray]], digits: int = 12) -> None:
    """Write output columns as CSV with a header line (digits significant digits; 17 round-trips a double
    exactly). columns: a dict of equal-length columns, or an iterable of such dicts whose rows follow one another
    (the header from the first; memory then holds one at a time)."""
    import numpy as np

    with open(path, "w") as file:
        for index, chunk in enumerate([columns] if isinstance(columns, dict) else columns):
            np.savetxt(
                file,
                np.column_stack(list(chunk.values())),
                delimiter=",",
                header=",".join(chunk) if index == 0 else "",
                comments="",
                fmt=f"%.{digits}g",
            )


def format_engine(report: dict) -> str:
    """The human-readable analysis of an engine at constant speed (`mech-regulator engine`)."""
    geometry, piston, cylinders, torque = report["geometry"], report["piston"], report["cylinders"], report["torque"]
    error = piston["approximation_error"]
    strokes = "four-stroke" if cylinders["cycle_deg"] == 720.0 else "two-stroke"
    lines = [
        f"scene {report['scene']}: engine at omega = {report['omega']:.6g} rad/s ({report['rpm']:.5g} rpm)",
        f"geometry: R = {geometry['crank']:g} m, l = {geometry['rod']:g} m, e = {geometry['offset']:g} m, "
        f"lambda = R/l = {geometry['lambda']:.4g}, k = e/R = {geometry['k']:.4g}; stroke S = "
        f"{geometry['stroke'] * 1000:.5g} mm, bore {geometry['bore'] * 1000:.4g} mm, displacement "
        f"{geometry['displacement'] * 1e6:.5g} cm^3",
        f"dead centres: top at phi = {geometry['top_dead_centre_deg']:.4g} deg, bottom at "
        f"{geometry['bottom_dead_centre_deg']:.5g} deg (source 002: alpha1 = {geometry['source_alpha1_deg']:.4g} "
        f"deg, alpha2 = {geometry['source_alpha2_deg']:.4g} deg from 180)",
        f"piston 1 (from the top dead centre): v max {piston['v_max']:.5g} m/s, mean speed S n / 30 = "
        f"{piston['mean_speed']:.5g} m/s; acceleration j {piston['a_max']:.6g} to {piston['a_min']:.6g} m/s^2, "
        f"at the top dead centre {piston['j_top']:.6g}, at the bottom {piston['j_bottom']:.6g} "
        f"(central formulas R w^2 (1 + lambda) = {piston['j_top_central_formula']:.6g}, "
        f"-R w^2 (1 - lambda) = {piston['j_bottom_central_formula']:.6g})",
        f"source 002's first-order formulas against the exact kinematics, largest error over the turn: "
        f"x {error['x'] * 1000:.3g} mm, v {error['v']:.3g} m/s, j {error['a']:.4g} m/s^2",
        f"cylinders: 1 ({strokes})"
        if cylinders["count"] == 1
        else f"cylinders: {cylinders['count']} ({strokes}), throws {_degrees(cylinders['throw_deg'])} deg"
        + (f", banks {_degrees(cylinders['bank_deg'])} deg" if any(cylinders["bank_deg"]) else "")
        + f"; firing order {'-'.join(map(str, cylinders['firing_order']))}, at "
        f"{_degrees(sorted(cylinders['firing_delay_deg']))} deg",
        f"mean indicated moment {torque['mean_gas']:.6g} N m, indicated power {torque['indicated_power'] / 1000:.5g} "
        f"kW, work per cycle {torque['indicated_work_per_cycle']:.6g} J, mean effective pressure "
        f"{torque['mean_effective_pressure'] / 1e5:.4g} bar; mean inertia moment {torque['mean_inertia']:.2g} N m",
        f"total moment (gas + inertia) from {torque['total_min']:.5g} to {torque['total_max']:.5g} N m",
        "largest harmonics, order: amplitude [N m] (phase [deg]), M = mean + sum A cos(order phi + phase):",
    ]
    for key, label in (("gas_harmonics", "gas"), ("inertia_harmonics", "inertia"), ("total_harmonics", "total")):
        lines.append(
            f"  {label:<8} "
            + ", ".join(f"{h['order']:g}: {h['amplitude']:.4g} ({h['phase_deg']:.0f})" for h in torque[key][:6])
        )
    return terminal_text("\n".join(lines + wrote_lines(report)))


def _degrees(values) -> str:
    return ", ".join(f"{value:g}" for value in values)


def format_kinematics(summary: dict) -> str:
    """The human-readable joint motion over one turn (`mech-regulator kinematics`): per joint its x and y ranges
    [m], largest speed [m/s] and acceleration [m/s^2] and the crank angles [deg] where they occur; then, where the
    mechanism's kinetostatics is built, the balancing moment's range and each joint's largest reaction, else why
    there are none."""
    driven = " (the driven part's, behind the coupling; omega its speed)" if summary.get("driven_part") else ""
    lines = [
        f"scene {summary['scene']}: {summary['mechanism']}{driven} at omega = {summary['omega']:g} rad/s, "
        f"{summary['points']} crank angles over a turn",
        f"{'joint':<6}{'x range [m]':>22}{'y range [m]':>22}{'v_max [m/s]':>14}{'at [deg]':>10}"
        f"{'a_max [m/s^2]':>16}{'at [deg]':>10}",
    ]
    for name, joint in summary["joints"].items():
        lines.append(
            f"{name:<6}{joint['x_min']:>11.5g}{joint['x_max']:>11.5g}{joint['y_min']:>11.5g}"
            f"{joint['y_max']:>11.5g}{joint['v_max']:>14.5g}{joint['v_max_at_deg']:>10.4g}"
            f"{joint['a_max']:>16.5g}{joint['a_max_at_deg']:>10.4g}"
        )
    reactions = summary.get("reactions")
    if reactions is not None:
        moment = reactions["balancing_moment"]
        lines.append(
            f"joint reactions (inertia forces and weights at constant speed, nothing on the output): "
            f"balancing moment on the crank {moment['min']:.5g} N m at {moment['min_at_deg']:.4g} deg to "
            f"{moment['max']:.5g} N m at {moment['max_at_deg']:.4g} deg"
        )
        lines += [
            f"  {name:<16} |R| max {joint['R_max']:12.5g} N at {joint['R_max_at_deg']:.4g} deg"
            for name, joint in reactions.items()
            if name != "balancing_moment"
        ]
    if "no_reactions" in summary:
        lines.append(f"no joint reactions: {summary['no_reactions']}")
    return terminal_text("\n".join(lines + wrote_lines(summary)))


OUTPUT_KEYS = ("csv", "scene_out", "plot", "recording", "bag")


def wrote_lines(data: dict) -> list[str]:
    """'wrote PATH' for each file a command wrote: the OUTPUT_KEYS its answer holds, in that order."""
    return [f"wrote {data[key]}" for key in OUTPUT_KEYS if key in data]


def check_outputs(args, *others: Path | None) -> None:
    """Give args.plot a .png suffix and refuse, before any work, output paths (the plot and others) that cannot
    be written (check_output_paths)."""
    plot = getattr(args, "plot", None)
    if plot is not None and not plot.suffix:
        args.plot = plot = plot.with_suffix(".png")
    check_output_paths(*others, plot)


def check_output_paths(*paths: Path | None) -> None:
    """Refuse, before any work, output files that cannot be written: SceneError naming the first such path and why
    (output_refusal), or two outputs that are one file. None stands for an output not asked for."""
    from mech_regulator.scene import SceneError

    seen: set[str] = set()
    for path in paths:
        if path is None:
            continue
        problem = output_refusal(path)
        if problem is None and os.path.realpath(path) in seen:
            problem = "two of the command's outputs would be this one file"
        if problem is not None:
            raise SceneError(f"cannot write '{path}': {problem}")
        seen.add(os.path.realpath(path))


KERNEL_FOLDERS = (Path("/dev"), Path("/proc"), Path("/sys"))
"""The kernel's file systems (devices, processes, settings): no output is ever written there."""


def output_refusal(path: Path) -> str | None:
    """Why the output file `path` cannot be written, or None: it is in KERNEL_FOLDERS or is not a regular file (a
    device, a pipe, a socket, a folder); its folder does not exist; or a first byte cannot be written (a read-only
    file system, no permission, a full disk), tried by writing one: a new file is made with it and removed, an
    existing one has its first byte written over with itself (an empty one gets one, taken away again)."""
    real = Path(os.path.realpath(path))  # where a symbolic link leads
    for kernel in KERNEL_FOLDERS:
        if real == kernel or kernel in real.parents:
            return (
                f"it is in {kernel}, the kernel's (devices, processes, settings): expected a regular file in a "
                "folder of yours"
            )
    try:
        mode = os.stat(real).st_mode
    except FileNotFoundError:
        mode = None
    except OSError as error:
        return error.strerror or str(error)
    if mode is not None and stat.S_ISDIR(mode):
        return "it is a folder"
    if mode is not None and not stat.S_ISREG(mode):
        return "it is a device, a pipe or a socket, not a regular file"
    if not real.parent.is_dir():
        return f"the folder '{path.parent}' does not exist"
    made = False
    try:
        if mode is None:
            with open(real, "xb") as probe:
                made = True
                probe.write(b"\0")
            real.unlink()
        else:
            with open(real, "r+b") as probe:
                first = probe.read(1)
                probe.seek(0)
                probe.write(first or b"\0")
                probe.flush()
                if not first:
                    probe.truncate(0)
    except OSError as error:
        if made:
            real.unlink(missing_ok=True)
        return error.strerror or str(error)
    return None


def output_folder(folder: Path, option: str = "--out") -> Path:
    """A command's output folder, made now if missing (with its parents), and checked to take files
    (output_refusal of a probe file in it): SceneError naming the option and the folder otherwise."""
    from mech_regulator.scene import SceneError

    if folder.exists() and not folder.is_dir():
        raise SceneError(f"{option} '{folder}': expected a folder, and it is a file or a device")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise SceneError(f"{option} '{folder}': cannot make the folder: {error.strerror or error}") from None
    problem = output_refusal(folder / f".mech-regulator-probe-{os.getpid()}")
    if problem is not None:
        raise SceneError(f"{option} '{folder}': cannot write in the folder: {problem}")
    return folder


class OutputWriter:
    """Writes a command's output files after its work, one by one: a write that fails then (a disk that fills up,
    an I/O error) is kept as one line and the other outputs are still written; the answer gets the key of each file
    written (wrote_lines)."""

    def __init__(self, answer: dict):
        self.answer = answer
        self.failures: list[str] = []

    def write(self, key: str, path: Path | None, write) -> None:
        """write(path), unless path is None; on success answer[key] = path."""
        if path is None:
            return
        try:
            write(path)
        except OSError as error:
            self.failures.append(f"writing '{path}' failed: {error.strerror or error}; that file is incomplete")
            return
        self.answer[key] = str(path)

    def exit_code(self, code: int) -> int:
        """Print each failure as a line on stderr; the command's exit code: EXIT_RUN_FAILED when a write failed and
        the command would otherwise have succeeded (0, or EXIT_INACCURATE of simulate --strict), else `code`."""
        for line in self.failures:
            print(f"mech-regulator: {terminal_text(line)}", file=sys.stderr)
        return EXIT_RUN_FAILED if self.failures and code in (0, EXIT_INACCURATE) else code


def write_rows_csv(path, rows: list[dict], digits: int = 17) -> None:
    """Write rows of mixed values (numbers, text, booleans) as CSV with a header line, the first row's keys in
    order: numbers with `digits` significant digits (17 round-trips a double), None as an empty field, text
    quoted where it needs to be (the csv module)."""
    import csv

    def field(value):
        if isinstance(value, float):
            return f"{value:.{digits}g}"
        return "" if value is None else value

    with open(path, "w", newline="", encoding="utf-8") as file:
        writer = csv.writer(file)
        writer.writerow(list(rows[0]) if rows else [])
        writer.writerows([field(value) for value in row.values()] for row in rows)


def bench_scenes_and_folder(scenes: str | None, out: Path, example: str) -> list[str] | None:
    """A benchmark's --scenes (comma-separated names; None: its default scenes) and its --out folder, made now and
    checked (output_folder): SceneError for an empty list (the message shows `example`) or a folder that cannot be
    made or written in."""
    from mech_regulator.scene import SceneError

    names = None if scenes is None else [name.strip() for name in scenes.split(",") if name.strip()]
    if names == []:
        raise SceneError(f"--scenes: expected scene names separated by commas, e.g. {example}")
    output_folder(out)
    return names
