"""The picture of the speed benchmark (`mech-regulator bench speed`): the work–precision of every path on the
crank–slider (CPU time against achieved error, log–log, the target error marked), the cost against simulated
time and, with --ros, the lockstep run's real-time factor against the exchange step's error."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (the backend must be chosen first)

from mech_regulator.bench.speed import TARGETS  # noqa: E402
from mech_regulator.bench.speed_precision import TARGET_ERROR, work_precision_front  # noqa: E402
from mech_regulator.bench.speed_ros import ROS_SCENE, ros_summary  # noqa: E402
from mech_regulator.bench.speed_runs import (  # noqa: E402
    BENCH_SCENE,
    FAST,
    MUJOCO,
    PATHS,
    REFERENCE,
    SOLVE_IVP,
    SpeedBenchmark,
)
from mech_regulator.bench.speed_scaling import SCALING_RTOL  # noqa: E402
from mech_regulator.viz.work_precision import X_LABEL  # noqa: E402

# (path, method) -> (colour, marker, line style): a colour per path, a line style per method
STYLE = {
    (FAST, "RK45"): ("tab:green", "o", "--"),
    (FAST, "DOP853"): ("tab:green", "o", "-"),
    (REFERENCE, "DOP853"): ("tab:blue", "s", "-"),
    (SOLVE_IVP, "RK45"): ("tab:orange", "^", "--"),
    (SOLVE_IVP, "DOP853"): ("tab:orange", "^", "-"),
    (MUJOCO, "RK4"): ("tab:red", "D", "-"),
}


def plot_speed(benchmark: SpeedBenchmark, path: Path, scene: str = BENCH_SCENE) -> None:
    """Left: CPU time [s] against achieved error [-] of every path and method on `scene`, points labelled with
    their setting (rtol; MuJoCo's timestep), faded where a cheaper run of the same line is more accurate, and
    TARGET_ERROR as a dotted line. Middle: CPU time [s] against simulated time [s], with the line of cost
    proportional to simulated time through the shortest run. Right, when the ROS run was measured: real-time factor
    against the exchange step's achieved error, the nodes and the same co-simulation in one process (_plot_ros)."""
    ros = ros_summary(benchmark)
    figure, axes = plt.subplots(
        1,
        3 if ros else 2,
        figsize=(21 if ros else 15, 6.5),
        width_ratios=(1.6, 1.0, 1.0) if ros else (1.6, 1.0),
        constrained_layout=True,
    )
    precision, growth = axes[:2]
    if ros:
        _plot_ros(axes[2], ros)
    for key in PATHS:
        rows = [row for row in benchmark.of("precision", scene=scene, path=key[0], method=key[1]) if row.error > 0]
        if not rows:
            continue
        colour, marker, style = STYLE[key]
        rows.sort(key=lambda row: row.cpu_s)
        front = work_precision_front(rows)
        precision.plot(
            [row.error for row in rows],
            [row.cpu_s for row in rows],
            color=colour,
            ls=style,
            lw=1.2,
            marker=marker,
            ms=5,
            label=f"{key[0]} {key[1]}",
        )
        for row in rows:
            label = f"{row.value * 1e3:g} ms" if row.setting == "timestep" else f"{row.value:.0e}"
            precision.annotate(
                label,
                (row.error, row.cpu_s),
                xytext=(4, 3),
                textcoords="offset points",
                fontsize=7,
                color=colour,
                alpha=1.0 if row in front else 0.45,
            )
    precision.axvline(TARGET_ERROR, color="k", lw=0.9, ls=":", label=f"target error {TARGET_ERROR:g}")
    precision.set_xscale("log")
    precision.set_yscale("log")
    precision.invert_xaxis()
    precision.grid(which="major", alpha=0.35)
    precision.grid(which="minor", alpha=0.1)
    precision.set(
        xlabel=X_LABEL + "\n(more accurate to the right)",
        ylabel="CPU time of the run [s] (median)",
        title=f"{scene}: work–precision of the four paths",
    )
    precision.legend(loc="upper left", fontsize=9, title="path, method; points: rtol or timestep", title_fontsize=8)
    for key in ((FAST, "DOP853"), (REFERENCE, "DOP853")):
        rows = benchmark.of("duration", path=key[0])
        if rows:
            colour, marker, style = STYLE[key]
            growth.plot(
                [row.value for row in rows],
                [row.cpu_s for row in rows],
                color=colour,
                ls=style,
                marker=marker,
                label=f"{key[0]} DOP853",
            )
            proportional = rows[0].cpu_s * rows[-1].value / rows[0].value
            growth.plot(
                [rows[0].value, rows[-1].value],
                [rows[0].cpu_s, proportional],
                color=colour,
                lw=0.8,
                ls=":",
                label=f"{key[0]}: proportional to simulated time",
            )
    growth.set_xscale("log")
    growth.set_yscale("log")
    growth.grid(which="major", alpha=0.35)
    growth.grid(which="minor", alpha=0.1)
    growth.set(
        xlabel="simulated time [s]",
        ylabel="CPU time of the run [s] (median)",
        title=f"{BENCH_SCENE}: cost against simulated time\n(DOP853, rtol {SCALING_RTOL:g})",
    )
    if growth.lines:
        growth.legend(fontsize=9)
    figure.savefig(path, dpi=110)
    plt.close(figure)


def plot_ros_speed(benchmark: SpeedBenchmark, path: Path) -> bool:
    """The ROS panel of plot_speed alone, larger, its legend beside it (docs/ros.md's picture); False (nothing
    written) when the benchmark did not measure the ROS main job."""
    ros = ros_summary(benchmark)
    if not ros:
        return False
    figure, axis = plt.subplots(figsize=(12, 6.5), constrained_layout=True)
    _plot_ros(axis, ros)
    axis.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0)
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return True


def _plot_ros(axis, ros: list[dict]) -> None:
    """Real-time factor (simulated s per wall s of the nodes' exchanges; per CPU s in one process) against the
    exchange's achieved error (omega, max, relative) on ROS_SCENE, each point labelled with its exchange step, run's
    default marked; the target (TARGETS) and real time as horizontal lines."""
    ros = [item for item in ros if item["scene"] == ROS_SCENE]
    for path, coupling, colour in (
        (FAST, "hold", "tab:green"),
        (REFERENCE, "hold", "tab:blue"),
        (FAST, "waveform", "tab:orange"),
        (FAST, "corrected", "tab:red"),
    ):
        items = [item for item in ros if item["path"] == path and item["coupling"] == coupling and "max_error" in item]
        for key, marker, style, how in (
            ("real_time_factor", "o", "-", "four node processes"),
            ("in_process_real_time_factor", "s", "--", "one process, no ROS"),
        ):
            points = [item for item in items if key in item]
            if not points:
                continue
            axis.plot(
                [item["max_error"] for item in points],
                [item[key] for item in points],
                color=colour,
                ls=style,
                marker=marker,
                label=f"{path} path, {coupling}, {how}",
            )
            for item in points:
                label = f"{item['exchange_step_s'] * 1e3:g} ms" + (" (default)" if item["default"] else "")
                axis.annotate(
                    label,
                    (item["max_error"], item[key]),
                    xytext=(4, 3),
                    textcoords="offset points",
                    fontsize=7,
                    color=colour,
                )
    axis.axhline(
        TARGETS["ROS real-time factor"],
        color="k",
        lw=0.9,
        ls=":",
        label=f"target: {TARGETS['ROS real-time factor']:g} x real time at run's default",
    )
    axis.axvline(1e-4, color="k", lw=0.9, ls="--", label="target: omega within 1e-4")
    axis.axhline(1.0, color="0.5", lw=0.8, ls="-.", label="real time")
    axis.set_xscale("log")
    axis.set_yscale("log")
    axis.invert_xaxis()
    axis.grid(which="major", alpha=0.35)
    axis.grid(which="minor", alpha=0.1)
    axis.set(
        xlabel="the exchange's error: max |omega - omega_monolithic| / max |omega| [-]\n(more accurate to the right)",
        ylabel="real-time factor (simulated s per s)",
        title=f"{ROS_SCENE}: lockstep co-simulation of the whole scene\nreal-time factor against the exchange's error",
    )
    axis.legend(fontsize=8, loc="lower left")
