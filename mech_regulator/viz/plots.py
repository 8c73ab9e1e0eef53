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

PLOTTED_POINTS = 200_000
"""The most points of a run's curve against time a plot draws. A 1300-pixel panel shows no more; past it (a long run:
10 000 s at 2000 Hz is 2e7 samples) each of PLOTTED_POINTS / 2 stretches of samples is drawn as its least and greatest
value (plotted_columns), which keeps the ripple's band a stride over the samples would alias."""


def plotted_columns(
    model: MachineModel, times: np.ndarray, states: np.ndarray
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The run's output columns (MachineModel.columns) at its sample times [s] and states, as a plot draws them: all of
    them up to PLOTTED_POINTS samples; beyond, each stretch of `width` samples reduced, column by column, to its least
    and greatest value in the order they come (its envelope), drawn at the stretch's first and last time. The columns
    are computed a few hundred stretches at a time, so that the columns of every sample are never in memory at once."""
    count = times.size
    if count <= PLOTTED_POINTS:
        return times, model.columns(times, states)
    width = -(-count // (PLOTTED_POINTS // 2))
    chunk = width * 256
    edges: list[np.ndarray] = []
    envelopes: dict[str, list[np.ndarray]] = {}
    for start in range(0, count, chunk):
        stop = min(start + chunk, count)
        stretches = -(-(stop - start) // width)
        index = np.minimum(np.arange(start, start + stretches * width), stop - 1).reshape(stretches, width)
        edges.append(np.column_stack([times[index[:, 0]], times[index[:, -1]]]).ravel())
        rows = np.arange(stretches)
        for name, values in model.columns(times[start:stop], states[:, start:stop]).items():
            grouped = np.asarray(values)[index - start]
            least, greatest = grouped.argmin(axis=1), grouped.argmax(axis=1)
            first, last = np.minimum(least, greatest), np.maximum(least, greatest)
            envelopes.setdefault(name, []).append(np.column_stack([grouped[rows, first], grouped[rows, last]]).ravel())
    return np.concatenate(edges), {name: np.concatenate(parts) for name, parts in envelopes.items()}


def room_for_legend(axes, share: float = 0.35) -> None:
    """Raise the top of the y axis by `share` of its range so a legend at the top does not cover the curves."""
    low, high = axes.get_ylim()
    axes.set_ylim(low, high + share * (high - low))


def plot_run(
    model: MachineModel,
    trajectory: Trajectory,
    summary: dict,
    path: Path,
    samples: tuple[np.ndarray, np.ndarray] | None = None,
) -> None:
    """Four panels: omega(t) with the steady band, moments against t, omega over the last dynamic
    period against the crank angle, and J(phi) with dJ/dphi (or the works of the moments). samples: the output
    sample times [s] and states of a streamed run (analysis/stream.py, RunDigest.samples), whose trajectory holds
    only its tail (the last period is drawn from it); None: the run sampled off its trajectory."""
    if samples is None:
        times = trajectory.samples(max(model.scene.solver.sample_rate, 2000.0 / max(trajectory.t_end, 1e-9)))
        samples = times, trajectory(times)
    times, states = samples
    if model.clutch is not None:
        plot_clutch_run(model, trajectory, summary, times, states, path)
        return
    times, columns = plotted_columns(model, times, states)
    last = summary["steady"]["last_period"]
    figure, axes = plt.subplots(2, 2, figsize=(13, 8), constrained_layout=True)
    figure.suptitle(f"{model.scene.name}: {model.scene.solver.method}, {summary['status']}")

    speed = axes[0, 0]
    speed.plot(times, columns["omega"], color="tab:blue", lw=1.0, label="omega")
    if last is not None:
        speed.axhline(last["omega_m"], color="k", lw=0.8, ls="--", label=f"omega_m = {last['omega_m']:.4g} rad/s")
        speed.axhspan(
            last["omega_min"], last["omega_max"], color="tab:orange", alpha=0.25, label=f"delta = {last['delta']:.3g}"
        )
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
        if "M_joint_friction" in period_columns:
            moments.plot(angle, period_columns["M_joint_friction"], lw=1.0, label="M_joint_friction (part of M_load)")
        moments.legend(loc="best", fontsize="small")
    moments.set(
        xlabel="crank angle within the last dynamic period [deg]",
        ylabel="reduced moment [N m]",
        title="moments on the crank",
    )

    cycle = axes[1, 0]
    if last is not None:
        window = np.linspace(last["t_start"], last["t_end"], 1000)
        phi, omega = trajectory(window)[:2]
        cycle.plot(np.degrees(phi - phi[0]), omega, color="tab:blue")
        cycle.axhline(last["omega_max"], color="tab:orange", lw=0.8, ls="--", label="omega_max, omega_min")
        cycle.axhline(last["omega_min"], color="tab:orange", lw=0.8, ls="--")
        cycle.legend(loc="lower right")
    cycle.set(
        xlabel="crank angle within the last dynamic period [deg]",
        ylabel="omega [rad/s]",
        title="speed over the last dynamic period",
    )

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
        right.set(
            xlabel="work over the run [J]",
            title=f"works (energy residual {summary['energy']['relative_residual']:.1g} relative)",
        )
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
    panel.plot(
        peak["time"],
        peak["moment"],
        "v",
        color="k",
        ms=8,
        label=f"largest {peak['moment']:.4g} N m at {peak['time']:.3g} s (period {peak['period']})",
    )
    if peak["steady_mean"] is not None:
        panel.axhline(
            peak["steady_mean"],
            color="k",
            lw=0.8,
            ls="--",
            label=f"steady mean {peak['steady_mean']:.4g} N m (peak x{peak['ratio']:.3g})",
        )
    start = periods["start_up_end"] if periods["start_up_end"] is not None else times[-1]
    steady = periods["steady_from"] if periods["steady_from"] is not None else times[-1]
    for axis in (speed, panel):
        for number, (lo, hi) in enumerate(((times[0], start), (start, steady), (steady, times[-1])), start=1):
            if hi > lo:
                axis.axvspan(
                    lo,
                    hi,
                    color=PERIOD_COLOURS[number - 1],
                    alpha=0.08,
                    label=f"period {number}" if axis is panel else None,
                )
    panel.set(xlabel="t [s]", ylabel="coupling moment M_m [N m]", title="coupling moment and periods of motion")
    room_for_legend(panel, 0.45)
    panel.legend(loc="upper right", fontsize=8, ncol=2)


def plot_required_coupling(result, name: str, path: Path) -> None:
    """The inverse problem (analysis.two_mass.RequiredCoupling): the prescribed driven speed law with the driving
    speed it implies, the twist and the needed coupling moment over the tabulated stretch, and the required
    characteristic with its table."""
    figure, axes = plt.subplots(1, 3, figsize=(16, 5), constrained_layout=True)
    figure.suptitle(
        f"{name}: coupling characteristic for the prescribed speed law "
        f"({'realisable' if result.realisable else 'NOT realisable'} by an elastic coupling)"
    )
    times, periodic = result.times, result.periodic_from
    law = axes[0]
    law.plot(times, result.omega_driven, color="tab:purple", lw=1.0, label="omega_driven (prescribed)")
    law.plot(
        times[:periodic],
        result.omega_driving[:periodic],
        color="tab:blue",
        lw=1.0,
        label="omega, driving part (from rest)",
    )
    law.plot(
        times[periodic:],
        result.omega_driving[periodic:],
        color="tab:cyan",
        lw=1.5,
        label="omega, driving part's periodic motion",
    )
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
    characteristic.plot(result.table_twist, result.table_moment, "k.-", lw=0.6, ms=3, label="table (continued to 0, 0)")
    characteristic.plot(
        result.twist[stretch],
        result.elastic[stretch],
        color="tab:blue",
        lw=1.5,
        alpha=0.7,
        label=f"{result.stretch}: loop width {result.loop_width:.2g} N m",
    )
    characteristic.axhline(0.0, color="k", lw=0.5)
    characteristic.axvline(0.0, color="k", lw=0.5)
    characteristic.set(
        xlabel="twist [rad]",
        ylabel="elastic moment M_m - c (omega - omega_driven) [N m]",
        title="required characteristic",
    )
    characteristic.grid(alpha=0.3)
    characteristic.legend(loc="upper left", fontsize=8)
    figure.savefig(path, dpi=100)
    plt.close(figure)


def _plot_governor_run(
    model: MachineModel, trajectory: Trajectory, summary: dict, times: np.ndarray, columns: dict, speed, panel
) -> None:
    """Governed run: the cycle-mean speed and predicted operating speeds on the speed panel; sleeve
    position and throttle against time, with the governor's mode changes, on `panel`."""
    from mech_regulator.analysis import cycle_mean_speed, operating_point

    held = times >= trajectory.t_kept  # a streamed run's tail (analysis/stream.py): the whole run when not streamed
    speed.plot(
        times[held],
        cycle_mean_speed(model, trajectory, times[held]),
        color="k",
        lw=1.2,
        label="cycle mean" if held[0] else f"cycle mean (from {trajectory.t_kept:.4g} s: the tail a long run keeps)",
    )
    levels = [model.external_load(0.0)] + [event.torque for event in model.scene.scenario.load_events]
    for level in dict.fromkeys(levels):
        predicted = operating_point(model, level).speed
        speed.axhline(predicted, color="tab:green", lw=0.8, ls="-.")
        speed.annotate(
            f"statics, load {level:g} N m",
            (times[-1], predicted),
            fontsize=7,
            color="tab:green",
            va="bottom",
            ha="right",
        )
    speed.legend(loc="lower right")
    governor = model.governor
    assert governor is not None, "plot_run draws a governor's panel for a governed model only"
    key, label, factor, unit = governor.plotted()  # a sleeve z [mm], a PI governor's integral part x [-]
    signal = columns[key] * factor
    panel.plot(times, signal, color="tab:purple", lw=1.0, label=label)
    stops = governor.sensor.stroke if governor.sensor is not None else ()
    for stop in stops:
        panel.axhline(stop * factor, color="tab:purple", lw=0.6, ls=":")
    panel.set(xlabel="t [s]", ylabel=f"{label} [{unit}]" + (" (dotted: stops)" if stops else ""), title="governor")
    throttle = panel.twinx()
    throttle.plot(times, columns["throttle"], color="tab:red", lw=1.0, label="throttle")
    throttle.set_ylim(-0.05, 1.05)
    throttle.set_ylabel("throttle [-]", color="tab:red")
    events = [t for t, _ in trajectory.events]
    if events:
        panel.plot(events, np.interp(events, times, signal), "k|", ms=6, label=f"mode changes ({len(events)})")
    panel.legend(loc="upper left")


def plot_clutch_run(
    model: MachineModel, trajectory: Trajectory, summary: dict, times: np.ndarray, states: np.ndarray, path: Path
) -> None:
    """A start-up through a friction clutch: motor and machine speeds, the clutch's torque against its static
    and kinetic limits with the motor's moment, the torque in each branch's section with the paper's estimate,
    and the works of the run; slip phases shaded (and stretches with the driven part held at rest hatched). times,
    states: the run's samples, to which the events the trajectory holds (all but a streamed run's early ones) are
    added."""
    events = np.array([t for t, _ in trajectory.events if trajectory.t_kept <= t <= trajectory.t_end])
    times, order = np.unique(np.concatenate([times, events]), return_index=True)
    states = np.hstack([states, trajectory(events)] if events.size else [states])[:, order]
    times, columns = plotted_columns(model, times, states)
    train = summary["drive_train"]
    clutch = model.clutch
    assert clutch is not None, "plot_clutch_run draws a model with a clutch"
    figure, axes = plt.subplots(2, 2, figsize=(13, 8), constrained_layout=True)
    figure.suptitle(
        f"{model.scene.name}: start-up through a friction clutch ({model.scene.solver.method}, {summary['status']})"
    )

    def shade(panel) -> None:
        for index, (start, end, _) in enumerate(train["clutch"]["slip_phases"]):
            panel.axvspan(
                start, end, color="tab:orange", alpha=0.15, lw=0, label=("clutch slips" if index == 0 else None)
            )
        for index, (start, end) in enumerate(train["held"]):
            panel.axvspan(
                start,
                end,
                facecolor="none",
                edgecolor="tab:gray",
                hatch="//",
                lw=0,
                label=("machine held at rest" if index == 0 else None),
            )

    speed = axes[0, 0]
    shade(speed)
    speed.plot(times, columns["omega"], color="tab:blue", lw=1.2, label="motor omega")
    speed.plot(times, columns["omega_driven"], color="tab:green", lw=1.2, label="machine omega_driven")
    for t in train["clutch"]["lock_times"]:
        speed.axvline(t, color="k", lw=0.8, ls=":")
        speed.annotate(
            f"locks at {t:.4g} s", (t, speed.get_ylim()[0]), xytext=(4, 6), textcoords="offset points", fontsize=8
        )
    speed.set(xlabel="t [s]", ylabel="speed [rad/s]", title="motor and machine (main shaft) speeds")
    speed.legend(loc="lower right", fontsize=8)

    torque = axes[0, 1]
    shade(torque)
    torque.plot(times, columns["M_drive"], color="tab:blue", lw=1.0, label="motor moment M_d")
    torque.plot(times, columns["clutch_torque"], color="tab:red", lw=1.4, label="clutch torque (to the machine)")
    torque.axhline(
        clutch.static_torque, color="tab:red", lw=0.8, ls="--", label=f"static limit {clutch.static_torque:g} N m"
    )
    torque.axhline(
        clutch.kinetic_torque, color="tab:red", lw=0.8, ls=":", label=f"kinetic {clutch.kinetic_torque:g} N m"
    )
    torque.set(xlabel="t [s]", ylabel="moment [N m]", title="clutch torque and motor moment")
    torque.legend(loc="upper right", fontsize=8)

    sections = axes[1, 0]
    shade(sections)
    for index, (name, section) in enumerate(train["sections"].items()):
        color = f"C{index + 4}"
        sections.plot(times, columns[f"M_section_{name}"], color=color, lw=1.2, label=f"{name} section")
        sections.plot(
            section["time"],
            section["max"],
            "o",
            color=color,
            ms=5,
            label=f"max {section['max']:.4g} N m at {section['time']:.3g} s",
        )
        if section["paper_estimate"] is not None:
            sections.axhline(
                section["paper_estimate"],
                color=color,
                lw=0.8,
                ls="--",
                label=f"paper's estimate {section['paper_estimate']:.4g} N m",
            )
    sections.set(
        xlabel="t [s]",
        ylabel="torque in the section [N m]",
        title="branch sections: M_kr = M_n,c + (I_n / i_1n) domega/dt",
    )
    sections.legend(loc="upper right", fontsize=8)

    works = summary["energy"]["works"]
    bars = axes[1, 1]
    bars.barh(list(works), list(works.values()), color="tab:green")
    bars.set(
        xlabel="work over the run [J]",
        title=f"works (energy residual {summary['energy']['relative_residual']:.1g} relative)",
    )
    figure.savefig(path, dpi=100)
    plt.close(figure)


def plot_governor(model: MachineModel, analysis: dict, path: Path) -> None:
    """Statics and stability of a governor: static characteristic with the insensitivity band and the
    operating points, throttle against speed at the operating points, eigenvalues of the averaged model
    and (periodic machines) the Floquet multipliers against exp(lambda T)."""
    characteristic = analysis["characteristic"]
    figure, axes = plt.subplots(2, 2, figsize=(13, 8), constrained_layout=True)
    figure.suptitle(
        f"{model.scene.name}: {analysis['kind']} governor"
        + (f", {analysis['feedback']} feedback" if analysis["feedback"] else "")
    )

    static = axes[0, 0]
    if characteristic is None:  # PI: isochronous, no sleeve; the throttle at each operating point
        set_speed = analysis["set_speed"]
        characteristic = {"speed_low": [0.95 * set_speed], "speed_high": [1.05 * set_speed]}
        static.axvline(set_speed, color="tab:blue", label=f"set speed, statism {analysis['statism']:.3g}")
        values, axis_label, title = (
            [point["throttle"] for point in analysis["operating_points"]],
            "throttle [-]",
            "isochronous (PI): the set speed at every load",
        )
    else:
        sleeve = np.array(characteristic["sleeve"]) * 1000.0
        static.fill_betweenx(
            sleeve,
            characteristic["speed_low"],
            characteristic["speed_high"],
            color="tab:orange",
            alpha=0.3,
            label="insensitivity band (static friction)",
        )
        static.plot(
            characteristic["speed"], sleeve, color="tab:blue", label=f"equilibrium, statism {analysis['statism']:.3g}"
        )
        values, axis_label, title = (
            [point["sleeve"] * 1000.0 for point in analysis["operating_points"]],
            "sleeve z [mm]",
            "static characteristic",
        )
    for point, value in zip(analysis["operating_points"], values):
        static.plot(
            point["speed"], value, "o", ms=6, label=f"load {point['external_load']:g} N m: {point['speed']:.4g} rad/s"
        )
    static.set(xlabel="crank speed omega [rad/s]", ylabel=axis_label, title=title)
    static.legend(loc="upper left", fontsize=8)

    balance = axes[0, 1]
    speeds = np.linspace(np.nanmin(characteristic["speed_low"]), np.nanmax(characteristic["speed_high"]), 60)
    averages = np.array([model.cycle_averages(w)[1:] for w in speeds])
    for point in analysis["operating_points"]:
        load = np.array([-model.cycle_averages(w, point["external_load"])[2] for w in speeds])
        (line,) = balance.plot(
            speeds, load / averages[:, 0], lw=1.0, label=f"throttle needed, load {point['external_load']:g} N m"
        )
        balance.plot(point["speed"], point["throttle"], "o", ms=6, color=line.get_color())
    governor = model.governor
    assert governor is not None, "plot_governor draws a governed model's statics"
    valve = governor.valve
    if valve is not None:  # direct action
        balance.plot(
            characteristic["speed"],
            [valve(z / 1000.0) for z in sleeve],
            color="k",
            label="valve on the static characteristic",
        )
    balance.set(
        xlabel="crank speed omega [rad/s]",
        ylabel="throttle [-]",
        ylim=(-0.05, 1.1),
        title="balance of the cycle-averaged machine",
    )
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
        circle.set_title(
            f"periodic orbit ({'stable' if floquet['stable'] else 'unstable'}), "
            f"T = {floquet['cycle_time'] * 1000:.3g} ms"
        )
    else:
        circle.set_title("Floquet multipliers: the machine is not periodic in phi")
    circle.set(xlabel="Re mu", ylabel="Im mu", aspect="equal")
    circle.grid(alpha=0.3)
    figure.savefig(path, dpi=100)
    plt.close(figure)


KINEMATICS_POSES = 4  # crank positions at which plot_kinematics draws the mechanism


def plot_kinematics(mechanism, columns: dict[str, np.ndarray], omega: float, title: str, path: Path) -> None:
    """Kinematics over one turn at constant crank speed omega [rad/s] (analysis.kinematics.kinematics_table):
    the paths of the moving points with the mechanism drawn at KINEMATICS_POSES crank angles (dark at phi = 0,
    where the points are named; left), and the
    points' speeds |v| and accelerations |a| against the crank angle (right); with the columns of
    analysis.kinematics.reactions_table, the joint reactions |R| and the balancing moment below them. Points moving
    alike (a walking beam's B and E, C and D) have identical curves: the later one is dashed."""
    from mech_regulator.analysis.kinematics import point_names
    from mech_regulator.mechanisms import point_motions
    from mech_regulator.mechanisms.drawing import mechanism_outline

    names = point_names(columns)
    joints = [key for key in columns if key.startswith("R_")]
    figure = plt.figure(figsize=(14, 10 if joints else 7), constrained_layout=True)
    grid = figure.add_gridspec(3 if joints else 2, 2, width_ratios=[1.25, 1.0])
    paths, speed, acceleration = (
        figure.add_subplot(grid[:, 0]),
        figure.add_subplot(grid[0, 1]),
        figure.add_subplot(grid[1, 1]),
    )
    figure.suptitle(f"{title}: kinematics over one turn at omega = {omega:g} rad/s")
    colours = dict(zip(names, plt.rcParams["axes.prop_cycle"].by_key()["color"]))
    for index, phi in enumerate(np.linspace(0.0, 2.0 * math.pi, KINEMATICS_POSES, endpoint=False)):
        outline = mechanism_outline(mechanism, phi)
        shade, width = ("0.15", 1.8) if index == 0 else ("0.7", 0.9)
        for part_name, part in outline.items():
            if part_name == "joints":
                paths.plot(part[:, 0], part[:, 1], "o", ms=4 if index == 0 else 2.5, color=shade, zorder=3)
            elif part_name != "crank_path":
                for strip in part if part.ndim == 3 else [part]:
                    paths.plot(strip[:, 0], strip[:, 1], color=shade, lw=width, zorder=2 if index == 0 else 1)
        paths.annotate(
            f"{math.degrees(phi):.0f}°",
            outline["crank"][-1],
            fontsize=8,
            color=shade,
            xytext=(4, 4),
            textcoords="offset points",
        )
    first = point_motions(mechanism)(0.0)
    for name in names:
        paths.annotate(
            name,
            (first[name][0].real, first[name][0].imag),
            fontsize=10,
            fontweight="bold",
            color=colours[name],
            xytext=(-12, 5),
            textcoords="offset points",
        )
    dphi = np.degrees(columns["phi"])
    for index, name in enumerate(names):
        twin = next(
            (
                other
                for other in names[:index]
                if all(
                    np.allclose(columns[f"{name}_{key}"], columns[f"{other}_{key}"], rtol=1e-9, atol=1e-12)
                    for key in ("vx", "vy")
                )
            ),
            None,
        )
        style = {"color": colours[name], "ls": "--" if twin else "-", "lw": 1.6 if twin else 1.2}
        label = f"{name} (moves as {twin})" if twin else name
        paths.plot(columns[f"{name}_x"], columns[f"{name}_y"], label=f"path of {label}", **style)
        speed.plot(dphi, columns[f"{name}_v"], label=label, **style)
        acceleration.plot(dphi, columns[f"{name}_a"], label=label, **style)
    paths.set(
        xlabel="x [m]",
        ylabel="y [m]",
        aspect="equal",
        title=f"paths of the joints; the mechanism at phi = 0 (dark) and {KINEMATICS_POSES - 1} more crank angles",
    )
    paths.legend(loc="best", fontsize=8)
    speed.set(ylabel="speed |v| [m/s]", title="speeds of the points")
    acceleration.set(
        xlabel="crank angle phi [deg]", ylabel="acceleration |a| [m/s^2]", title="accelerations of the points"
    )
    panels = [speed, acceleration]
    if joints:
        reactions = figure.add_subplot(grid[2, 1])
        for key in joints:
            reactions.plot(dphi, columns[key], lw=1.2, label=key[2:])
        balancing = reactions.twinx()
        balancing.plot(dphi, columns["M_balancing"], color="k", lw=1.0, ls=":", label="balancing moment (right axis)")
        balancing.set_ylabel("balancing moment M_b [N m]")
        reactions.set(
            xlabel="crank angle phi [deg]",
            ylabel="reaction |R| [N]",
            title="joint reactions and the balancing moment\n(kinetostatics at constant speed, with weights)",
        )
        handles, labels = (
            sum(pair, []) for pair in zip(reactions.get_legend_handles_labels(), balancing.get_legend_handles_labels())
        )
        reactions.legend(handles, labels, loc="upper right", fontsize=8, ncol=3)
        panels.append(reactions)
    for axes in panels:
        axes.set_xlim(0.0, 360.0)
        axes.set_xticks(np.arange(0, 361, 45))
        axes.grid(alpha=0.3)
        if axes is not panels[-1] or not joints:
            axes.legend(loc="upper right", fontsize=8, ncol=3)
    figure.savefig(path, dpi=100)
    plt.close(figure)


def plot_engine(model: MachineModel, omega: float, path: Path, max_order: float = 12.0) -> None:
    """An engine at constant speed omega [rad/s]: piston 1's displacement, velocity and acceleration over the
    turn (exact and source 002's approximation, from the top dead centre); gas moment per cylinder, total gas,
    inertia and total moments over the working cycle; amplitudes of their harmonics up to max_order."""
    from mech_regulator.analysis.engine import engine_parts, harmonics, piston_table, torque_curves

    phis, exact, approximate = piston_table(model, omega)
    curves = torque_curves(model, omega)
    mechanism, _ = engine_parts(model.scene)
    figure, axes = plt.subplot_mosaic(
        [["x", "torque"], ["v", "torque"], ["a", "spectrum"]],
        figsize=(14, 9),
        constrained_layout=True,
        gridspec_kw={"width_ratios": [1.0, 1.5]},
    )
    figure.suptitle(
        f"{model.scene.name}: engine at omega = {omega:.5g} rad/s ({omega * 30 / math.pi:.5g} rpm), "
        f"lambda = {mechanism.crank / mechanism.rod:.3g}, k = {mechanism.offset / mechanism.crank:.3g}"
    )
    from mech_regulator.mechanisms.crank_slider import dead_centres

    degrees = np.degrees(phis)
    scales = np.array([1000.0, 1.0, 1.0])  # x in mm
    errors = np.max(np.abs(exact - approximate), axis=1) * scales
    for row, (key, ylabel) in enumerate((("x", "x [mm]"), ("v", "v [m/s]"), ("a", "j [m/s^2]"))):
        axis = axes[key]
        axis.plot(degrees, exact[row] * scales[row], color="tab:blue", lw=1.5, label="exact")
        axis.plot(
            degrees,
            approximate[row] * scales[row],
            color="tab:orange",
            lw=1.0,
            ls="--",
            label="source 002, first order in lambda\n(largest errors {:.3g} mm, {:.3g} m/s, {:.3g} m/s^2)".format(
                *errors
            ),
        )
        for dead_centre in dead_centres(mechanism.crank, mechanism.rod, mechanism.offset):
            axis.axvline(math.degrees(dead_centre) % 360.0, color="grey", lw=0.6, ls=":")
        axis.set(ylabel=ylabel, xlim=(0.0, 360.0), xticks=np.arange(0, 361, 60))
        axis.grid(alpha=0.3)
    axes["x"].set_title("piston 1 from the top dead centre (dotted: dead centres)")
    axes["x"].legend(loc="lower center", fontsize=8)
    axes["a"].set_xlabel("crank angle phi [deg]")

    torque = axes["torque"]
    cycle_degrees = np.degrees(curves.phi)
    cylinder_colors = ["C0", "C1", "C4", "C6", "C8", "C9", "C5", "C7"]
    for i, row in enumerate(curves.gas if len(curves.gas) > 1 else []):
        torque.plot(
            cycle_degrees, row, lw=0.7, color=cylinder_colors[i % len(cylinder_colors)], label=f"gas, cylinder {i + 1}"
        )
    torque.plot(cycle_degrees, curves.gas_total, color="tab:red", lw=1.6, label="gas, total")
    torque.plot(cycle_degrees, curves.inertia, color="tab:green", lw=1.2, label="inertia -1/2 J' omega^2")
    torque.plot(cycle_degrees, curves.total, color="k", lw=1.8, label="total")
    mean = float(np.mean(curves.gas_total))
    torque.axhline(mean, color="tab:red", lw=0.8, ls="--", label=f"mean {mean:.4g} N m")
    torque.set(
        xlabel="crank angle phi [deg]",
        ylabel="moment on the crank [N m]",
        xlim=(0.0, cycle_degrees[-1] + 0.25),
        xticks=np.arange(0, cycle_degrees[-1] + 1, 90),
        title=f"moments over the working cycle ({len(curves.gas)} cylinder{'s' if len(curves.gas) > 1 else ''})",
    )
    torque.grid(alpha=0.3)
    room_for_legend(torque, 0.3)
    torque.legend(loc="upper center", fontsize=8, ncols=4)

    spectrum = axes["spectrum"]
    series = [
        ("gas", curves.gas_total, "tab:red"),
        ("inertia", curves.inertia, "tab:green"),
        ("total", curves.total, "k"),
    ]
    step = 2.0 * math.pi / curves.cycle
    width = 0.8 * step / len(series)
    for index, (name, values, color) in enumerate(series):
        fourier = harmonics(values, curves.cycle)
        shown = fourier.orders <= max_order + 1e-9
        spectrum.bar(
            fourier.orders[shown] + (index - 1) * width, fourier.amplitudes[shown], width=width, color=color, label=name
        )
    spectrum.set(
        xlabel="order (multiples of the crank speed)",
        ylabel="amplitude [N m]",
        xticks=np.arange(0.0, max_order + 0.5, 1.0),
        xlim=(0.0, max_order + 0.5),
        title="harmonics: M = mean + sum A_k cos(order_k phi + phase_k)",
    )
    spectrum.grid(alpha=0.3, axis="y")
    spectrum.legend(loc="upper right", fontsize=8)
    figure.savefig(path, dpi=100)
    plt.close(figure)
