"""PNG pictures of a run (matplotlib, no display needed)."""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (the backend must be chosen first)
import numpy as np  # noqa: E402

from mech_regulator.model import MachineModel  # noqa: E402
from mech_regulator.solvers import Trajectory  # noqa: E402


def plot_run(model: MachineModel, trajectory: Trajectory, summary: dict, path: Path) -> None:
    """Four panels: omega(t) with the steady band, moments against t, omega over the last dynamic
    period against the crank angle, and J(phi) with dJ/dphi (or the works of the moments)."""
    times = trajectory.samples(max(model.scene.solver.sample_rate, 2000.0 / max(trajectory.t_end, 1e-9)))
    columns = model.columns(times, trajectory(times))
    last = summary["steady"]["last_period"]
    figure, axes = plt.subplots(2, 2, figsize=(13, 8), constrained_layout=True)
    figure.suptitle(f"{model.scene.name}: {model.scene.solver.method}, {summary['status']}")

    speed = axes[0, 0]
    speed.plot(times, columns["omega"], color="tab:blue", lw=1.0, label="omega")
    if last is not None:
        speed.axhline(last["omega_m"], color="k", lw=0.8, ls="--", label=f"omega_m = {last['omega_m']:.4g} rad/s")
        speed.axhspan(last["omega_min"], last["omega_max"], color="tab:orange", alpha=0.25,
                      label=f"delta = {last['delta']:.3g}")
    for t in model.breakpoints():
        speed.axvline(t, color="tab:red", lw=0.8, ls=":")
    speed.set(xlabel="t [s]", ylabel="omega [rad/s]", title="crank speed")
    speed.legend(loc="lower right")

    moments = axes[0, 1]
    if last is not None:  # one dynamic period is readable; a whole run of an engine is a comb
        window = np.linspace(last["t_start"], last["t_end"], 1500)
        period_columns = model.columns(window, trajectory(window))
        angle = np.degrees(period_columns["phi"] - period_columns["phi"][0])
        moments.plot(angle, period_columns["M_drive"], lw=1.0, label="M_drive")
        moments.plot(angle, period_columns["M_load"], lw=1.0, label="M_load (all resisting)")
        if "M_weight" in period_columns:
            moments.plot(angle, period_columns["M_weight"], lw=1.0, label="M_weight")
        moments.legend(loc="lower right")
    moments.set(xlabel="crank angle within the last dynamic period [deg]", ylabel="reduced moment [N m]",
                title="moments on the crank")

    cycle = axes[1, 0]
    if last is not None:
        window = np.linspace(last["t_start"], last["t_end"], 1000)
        phi, omega = trajectory(window)[:2]
        cycle.plot(np.degrees(phi - phi[0]), omega, color="tab:blue")
        cycle.axhline(last["omega_max"], color="tab:orange", lw=0.8, ls="--", label="omega_max, omega_min")
        cycle.axhline(last["omega_min"], color="tab:orange", lw=0.8, ls="--")
        cycle.legend(loc="lower right")
    cycle.set(xlabel="crank angle within the last dynamic period [deg]", ylabel="omega [rad/s]",
              title="speed over the last dynamic period")

    right = axes[1, 1]
    if summary.get("two_mass"):
        _plot_two_mass_run(summary["two_mass"], times, columns, speed, right)
    elif model.governor is not None:
        _plot_governor_run(model, trajectory, summary, times, columns, speed, right)
    elif model.reduced is not None:
        phi = np.linspace(0.0, 2.0 * math.pi, 721)
        inertia = np.array([model.inertia(p) for p in phi])
        right.plot(np.degrees(phi), inertia[:, 0], color="tab:blue")
        right.set(xlabel="crank angle [deg]", ylabel="J(phi) [kg m^2]", title="reduced inertia and its derivative")
        slope = right.twinx()
        slope.plot(np.degrees(phi), inertia[:, 1], color="tab:red", lw=0.8)
        slope.set_ylabel("dJ/dphi [kg m^2/rad]", color="tab:red")
    else:
        works = summary["energy"]["works"]
        right.barh(list(works), list(works.values()), color="tab:green")
        right.set(xlabel="work over the run [J]", title=f"works (energy residual "
                                                         f"{summary['energy']['relative_residual']:.1g} relative)")
    figure.savefig(path, dpi=100)
    plt.close(figure)


PERIOD_COLOURS = ("tab:red", "tab:olive", "tab:green")  # shading of periods 1, 2, 3 of a two-mass run


def _plot_two_mass_run(periods: dict, times: np.ndarray, columns: dict, speed, panel) -> None:
    """Two-mass run: omega_driven on the speed panel; the coupling moment M_m against time with its largest
    value marked on `panel`; both with the periods (start-up, transient, steady) shaded."""
    speed.plot(times, columns["omega_driven"], color="tab:purple", lw=0.8, label="omega_driven")
    speed.legend(loc="lower right")
    passed = -columns["M_coupling"]
    panel.plot(times, passed, color="tab:blue", lw=0.8, label="M_m (coupling to the driven part)")
    peak = periods["peak"]
    panel.plot(peak["time"], peak["moment"], "v", color="k", ms=8,
               label=f"largest {peak['moment']:.4g} N m at {peak['time']:.3g} s (period {peak['period']})")
    if peak["steady_mean"] is not None:
        panel.axhline(peak["steady_mean"], color="k", lw=0.8, ls="--",
                      label=f"steady mean {peak['steady_mean']:.4g} N m (peak x{peak['ratio']:.3g})")
    start = periods["start_up_end"] if periods["start_up_end"] is not None else times[-1]
    steady = periods["steady_from"] if periods["steady_from"] is not None else times[-1]
    for axis in (speed, panel):
        for number, (lo, hi) in enumerate(((times[0], start), (start, steady), (steady, times[-1])), start=1):
            if hi > lo:
                axis.axvspan(lo, hi, color=PERIOD_COLOURS[number - 1], alpha=0.08,
                             label=f"period {number}" if axis is panel else None)
    panel.set(xlabel="t [s]", ylabel="coupling moment M_m [N m]", title="coupling moment and periods of motion")
    low, high = panel.get_ylim()
    panel.set_ylim(low, high + 0.45 * (high - low))  # room for the legend above the curve
    panel.legend(loc="upper right", fontsize=8, ncol=2)


def plot_required_coupling(result, name: str, path: Path) -> None:
    """The inverse problem (analysis.two_mass.RequiredCoupling): the prescribed driven speed law with the driving
    speed it implies, the twist and the needed coupling moment over the tabulated stretch, and the required
    characteristic with its table."""
    figure, axes = plt.subplots(1, 3, figsize=(16, 5), constrained_layout=True)
    figure.suptitle(f"{name}: coupling characteristic for the prescribed speed law "
                    f"({'realisable' if result.realisable else 'NOT realisable'} by an elastic coupling)")
    times, periodic = result.times, result.periodic_from
    law = axes[0]
    law.plot(times, result.omega_driven, color="tab:purple", lw=1.0, label="omega_driven (prescribed)")
    law.plot(times[:periodic], result.omega_driving[:periodic], color="tab:blue", lw=1.0,
             label="omega, driving part (from rest)")
    law.plot(times[periodic:], result.omega_driving[periodic:], color="tab:cyan", lw=1.5,
             label="omega, driving part's periodic motion")
    law.axvline(result.law.run_up, color="k", lw=0.8, ls=":", label=f"end of run-up T = {result.law.run_up:g} s")
    law.set(xlabel="t [s]", ylabel="speed [rad/s]", title="speeds")
    law.legend(loc="lower right", fontsize=8)
    stretch = slice(periodic, None) if result.stretch == "steady motion" else slice(None)
    twist = axes[1]
    twist.plot(times[stretch], result.twist[stretch], color="tab:green", lw=4.0, alpha=0.5)
    twist.set(xlabel="t [s]", title=f"twist and needed coupling moment ({result.stretch})")
    twist.set_ylabel("twist phi - phi_driven [rad]", color="tab:green")
    moment = twist.twinx()
    moment.plot(times[stretch], result.moment[stretch], color="tab:red", lw=1.0)
    moment.set_ylabel("needed coupling moment M_m [N m]", color="tab:red")
    characteristic = axes[2]
    characteristic.plot(result.table_twist, result.table_moment, "k.-", lw=0.6, ms=3,
                        label="table (continued to 0, 0)")
    characteristic.plot(result.twist[stretch], result.elastic[stretch], color="tab:blue", lw=1.5, alpha=0.7,
                        label=f"{result.stretch}: loop width {result.loop_width:.2g} N m")
    characteristic.axhline(0.0, color="k", lw=0.5)
    characteristic.axvline(0.0, color="k", lw=0.5)
    characteristic.set(xlabel="twist [rad]", ylabel="elastic moment M_m - c (omega - omega_driven) [N m]",
                       title="required characteristic")
    characteristic.grid(alpha=0.3)
    characteristic.legend(loc="upper left", fontsize=8)
    figure.savefig(path, dpi=100)
    plt.close(figure)


def _plot_governor_run(model: MachineModel, trajectory: Trajectory, summary: dict, times: np.ndarray,
                       columns: dict, speed, panel) -> None:
    """Governed run: the cycle-mean speed and predicted operating speeds on the speed panel; sleeve
    position and throttle against time, with the governor's mode changes, on `panel`."""
    from mech_regulator.analysis import cycle_mean_speed, operating_point

    speed.plot(times, cycle_mean_speed(model, trajectory, times), color="k", lw=1.2, label="cycle mean")
    levels = [model.external_load(0.0)] + [event.torque for event in model.scene.scenario.load_events]
    for level in dict.fromkeys(levels):
        predicted = operating_point(model, level).speed
        speed.axhline(predicted, color="tab:green", lw=0.8, ls="-.")
        speed.annotate(f"statics, load {level:g} N m", (times[-1], predicted), fontsize=7, color="tab:green",
                       va="bottom", ha="right")
    speed.legend(loc="lower right")
    stroke = model.governor.sensor.stroke
    panel.plot(times, columns["sleeve"] * 1000.0, color="tab:purple", lw=1.0, label="sleeve z")
    for stop in stroke:
        panel.axhline(stop * 1000.0, color="tab:purple", lw=0.6, ls=":")
    panel.set(xlabel="t [s]", ylabel="sleeve z [mm] (dotted: stops)", title="governor")
    throttle = panel.twinx()
    throttle.plot(times, columns["throttle"], color="tab:red", lw=1.0, label="throttle")
    throttle.set_ylim(-0.05, 1.05)
    throttle.set_ylabel("throttle [-]", color="tab:red")
    events = [t for t, _ in trajectory.events]
    if events:
        panel.plot(events, np.interp(events, times, columns["sleeve"] * 1000.0), "k|", ms=6,
                   label=f"mode changes ({len(events)})")
    panel.legend(loc="upper left")


def plot_governor(model: MachineModel, analysis: dict, path: Path) -> None:
    """Statics and stability of a governor: static characteristic with the insensitivity band and the
    operating points, throttle against speed at the operating points, eigenvalues of the averaged model
    and (periodic machines) the Floquet multipliers against exp(lambda T)."""
    characteristic = analysis["characteristic"]
    sleeve = np.array(characteristic["sleeve"]) * 1000.0
    figure, axes = plt.subplots(2, 2, figsize=(13, 8), constrained_layout=True)
    figure.suptitle(f"{model.scene.name}: {analysis['kind']} governor"
                    + (f", {analysis['feedback']} feedback" if analysis["feedback"] else ""))

    static = axes[0, 0]
    static.fill_betweenx(sleeve, characteristic["speed_low"], characteristic["speed_high"], color="tab:orange",
                         alpha=0.3, label="insensitivity band (static friction)")
    static.plot(characteristic["speed"], sleeve, color="tab:blue", label=f"equilibrium, statism {analysis['statism']:.3g}")
    for point in analysis["operating_points"]:
        static.plot(point["speed"], point["sleeve"] * 1000.0, "o", ms=6,
                    label=f"load {point['external_load']:g} N m: {point['speed']:.4g} rad/s")
    static.set(xlabel="crank speed omega [rad/s]", ylabel="sleeve z [mm]", title="static characteristic")
    static.legend(loc="upper left", fontsize=8)

    balance = axes[0, 1]
    speeds = np.linspace(np.nanmin(characteristic["speed_low"]), np.nanmax(characteristic["speed_high"]), 60)
    averages = np.array([model.cycle_averages(w)[1:] for w in speeds])
    for point in analysis["operating_points"]:
        load = np.array([-model.cycle_averages(w, point["external_load"])[2] for w in speeds])
        line, = balance.plot(speeds, load / averages[:, 0], lw=1.0,
                             label=f"throttle needed, load {point['external_load']:g} N m")
        balance.plot(point["speed"], point["throttle"], "o", ms=6, color=line.get_color())
    if model.governor.kind == "direct":
        balance.plot(characteristic["speed"], [model.governor.valve(z / 1000.0) for z in sleeve], color="k",
                     label="valve on the static characteristic")
    balance.set(xlabel="crank speed omega [rad/s]", ylabel="throttle [-]", ylim=(-0.05, 1.1),
                title="balance of the cycle-averaged machine")
    balance.legend(loc="best", fontsize=8)

    linear = analysis["linear"]
    plane = axes[1, 0]
    eigen = np.array(linear["eigenvalues"])
    plane.axvline(0.0, color="k", lw=0.8)
    plane.plot(eigen[:, 0], eigen[:, 1], "x", ms=9, mew=2, color="tab:red" if not linear["stable"] else "tab:blue")
    title = f"eigenvalues of the averaged model ({'stable' if linear['stable'] else 'unstable'})"
    if linear["vyshnegradsky"]:
        A, B = linear["vyshnegradsky"]
        title += f"\nVyshnegradsky A = {A:.3g}, B = {B:.3g}, AB = {A * B:.3g}"
    plane.set(xlabel="Re lambda [1/s]", ylabel="Im lambda [rad/s]", title=title)
    plane.grid(alpha=0.3)

    circle = axes[1, 1]
    floquet = analysis["floquet"]
    angle = np.linspace(0.0, 2.0 * math.pi, 361)
    circle.plot(np.cos(angle), np.sin(angle), color="k", lw=0.8)
    if floquet is not None:
        multipliers = np.array(floquet["multipliers"])
        averaged = np.array(floquet["averaged_multipliers"])
        circle.plot(multipliers[:, 0], multipliers[:, 1], "x", ms=9, mew=2, label="Floquet multipliers")
        circle.plot(averaged[:, 0], averaged[:, 1], "o", mfc="none", ms=10, label="exp(lambda T), averaged model")
        circle.legend(loc="lower left", fontsize=8)
        circle.set_title(f"periodic orbit ({'stable' if floquet['stable'] else 'unstable'}), "
                         f"T = {floquet['cycle_time'] * 1000:.3g} ms")
    else:
        circle.set_title("Floquet multipliers: the machine is not periodic in phi")
    circle.set(xlabel="Re mu", ylabel="Im mu", aspect="equal")
    circle.grid(alpha=0.3)
    figure.savefig(path, dpi=100)
    plt.close(figure)
