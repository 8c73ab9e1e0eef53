"""The text of the analysis commands' answers: `governor` (statics, stability), `coupling` (the inverse
problem's characteristic), `engine` (an engine at constant speed) and `kinematics` (the joints over a turn).

Light to import (the standard library only at module level): numpy, the model and the scene load inside the
functions that need them.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from mech_regulator.cli.report.machine_text import sleeve_text
from mech_regulator.cli.report.outputs import wrote_lines
from mech_regulator.cli.report.terminal import terminal_text

if TYPE_CHECKING:
    pass


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
            f"({point['speed'] * 30 / math.pi:.5g} rpm), {sleeve_text(point)}"
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
