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
    if model.clutch is not None:
        plot_clutch_run(model, trajectory, summary, times, path)
        return
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
    if model.governor is not None:
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


def plot_clutch_run(model: MachineModel, trajectory: Trajectory, summary: dict, times: np.ndarray, path: Path) -> None:
    """A start-up through a friction clutch: motor and machine speeds, the clutch's torque against its static
    and kinetic limits with the motor's moment, the torque in each branch's section with the paper's estimate,
    and the works of the run; slip phases shaded (and stretches with the driven part held at rest hatched)."""
    times = np.union1d(times, [t for t, _ in trajectory.events])
    columns = model.columns(times, trajectory(times))
    train = summary["drive_train"]
    clutch = model.clutch
    figure, axes = plt.subplots(2, 2, figsize=(13, 8), constrained_layout=True)
    figure.suptitle(f"{model.scene.name}: start-up through a friction clutch ({model.scene.solver.method}, "
                    f"{summary['status']})")

    def shade(panel) -> None:
        for index, (start, end, mode) in enumerate(train["clutch"]["slip_phases"]):
            panel.axvspan(start, end, color="tab:orange", alpha=0.15, lw=0,
                          label=("clutch slips" if index == 0 else None))
        for index, (start, end) in enumerate(train["held"]):
            panel.axvspan(start, end, facecolor="none", edgecolor="tab:gray", hatch="//", lw=0,
                          label=("machine held at rest" if index == 0 else None))

    speed = axes[0, 0]
    shade(speed)
    speed.plot(times, columns["omega"], color="tab:blue", lw=1.2, label="motor omega")
    speed.plot(times, columns["omega_driven"], color="tab:green", lw=1.2, label="machine omega_driven")
    for t in train["clutch"]["lock_times"]:
        speed.axvline(t, color="k", lw=0.8, ls=":")
        speed.annotate(f"locks at {t:.4g} s", (t, speed.get_ylim()[0]), xytext=(4, 6), textcoords="offset points",
                       fontsize=8)
    speed.set(xlabel="t [s]", ylabel="speed [rad/s]", title="motor and machine (main shaft) speeds")
    speed.legend(loc="lower right", fontsize=8)

    torque = axes[0, 1]
    shade(torque)
    torque.plot(times, columns["M_drive"], color="tab:blue", lw=1.0, label="motor moment M_d")
    torque.plot(times, columns["clutch_torque"], color="tab:red", lw=1.4, label="clutch torque (to the machine)")
    torque.axhline(clutch.static_torque, color="tab:red", lw=0.8, ls="--", label=f"static limit {clutch.static_torque:g} N m")
    torque.axhline(clutch.kinetic_torque, color="tab:red", lw=0.8, ls=":", label=f"kinetic {clutch.kinetic_torque:g} N m")
    torque.set(xlabel="t [s]", ylabel="moment [N m]", title="clutch torque and motor moment")
    torque.legend(loc="upper right", fontsize=8)

    sections = axes[1, 0]
    shade(sections)
    for index, (name, section) in enumerate(train["sections"].items()):
        color = f"C{index + 4}"
        sections.plot(times, columns[f"M_section_{name}"], color=color, lw=1.2, label=f"{name} section")
        sections.plot(section["time"], section["max"], "o", color=color, ms=5,
                      label=f"max {section['max']:.4g} N m at {section['time']:.3g} s")
        if section["paper_estimate"] is not None:
            sections.axhline(section["paper_estimate"], color=color, lw=0.8, ls="--",
                             label=f"paper's estimate {section['paper_estimate']:.4g} N m")
    sections.set(xlabel="t [s]", ylabel="torque in the section [N m]",
                 title="branch sections: M_kr = M_n,c + (I_n / i_1n) domega/dt")
    sections.legend(loc="upper right", fontsize=8)

    works = summary["energy"]["works"]
    bars = axes[1, 1]
    bars.barh(list(works), list(works.values()), color="tab:green")
    bars.set(xlabel="work over the run [J]", title=f"works (energy residual {summary['energy']['relative_residual']:.1g} "
                                                   "relative)")
    figure.savefig(path, dpi=100)
    plt.close(figure)


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
