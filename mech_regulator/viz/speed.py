"""The picture of the speed benchmark (`mech-regulator bench speed`): the work–precision of every path on the
crank–slider (CPU time against achieved error, log–log, the target error marked) and the cost against simulated
time."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (the backend must be chosen first)

from mech_regulator.bench.speed import (BENCH_SCENE, FAST, MUJOCO, PATHS, REFERENCE, SCALING_RTOL,  # noqa: E402
                                        SOLVE_IVP, TARGET_ERROR, SpeedBenchmark, work_precision_front)
from mech_regulator.viz.work_precision import X_LABEL  # noqa: E402

# (path, method) -> (colour, marker, line style): a colour per path, a line style per method
STYLE = {(FAST, "RK45"): ("tab:green", "o", "--"), (FAST, "DOP853"): ("tab:green", "o", "-"),
         (REFERENCE, "DOP853"): ("tab:blue", "s", "-"), (SOLVE_IVP, "RK45"): ("tab:orange", "^", "--"),
         (SOLVE_IVP, "DOP853"): ("tab:orange", "^", "-"), (MUJOCO, "RK4"): ("tab:red", "D", "-")}


def plot_speed(benchmark: SpeedBenchmark, path: Path, scene: str = BENCH_SCENE) -> None:
    """Left: CPU time [s] against achieved error [-] of every path and method on `scene`, points labelled with
    their setting (rtol; MuJoCo's timestep), faded where a cheaper run of the same line is more accurate, and
    TARGET_ERROR as a dotted line. Right: CPU time [s] against simulated time [s], with the line of cost
    proportional to simulated time through the shortest run."""
    figure, (precision, growth) = plt.subplots(1, 2, figsize=(15, 6.5), width_ratios=(1.6, 1.0),
                                               constrained_layout=True)
    for key in PATHS:
        rows = [row for row in benchmark.of("precision", scene=scene, path=key[0], method=key[1]) if row.error > 0]
        if not rows:
            continue
        colour, marker, style = STYLE[key]
        rows.sort(key=lambda row: row.cpu_s)
        front = work_precision_front(rows)
        precision.plot([row.error for row in rows], [row.cpu_s for row in rows], color=colour, ls=style, lw=1.2,
                       marker=marker, ms=5, label=f"{key[0]} {key[1]}")
        for row in rows:
            label = f"{row.value * 1e3:g} ms" if row.setting == "timestep" else f"{row.value:.0e}"
            precision.annotate(label, (row.error, row.cpu_s), xytext=(4, 3), textcoords="offset points", fontsize=7,
                               color=colour, alpha=1.0 if row in front else 0.45)
    precision.axvline(TARGET_ERROR, color="k", lw=0.9, ls=":", label=f"target error {TARGET_ERROR:g}")
    precision.set_xscale("log")
    precision.set_yscale("log")
    precision.invert_xaxis()
    precision.grid(which="major", alpha=0.35)
    precision.grid(which="minor", alpha=0.1)
    precision.set(xlabel=X_LABEL + "\n(more accurate to the right)", ylabel="CPU time of the run [s] (median)",
                  title=f"{scene}: work–precision of the four paths")
    precision.legend(loc="upper left", fontsize=9, title="path, method; points: rtol or timestep", title_fontsize=8)
    for key in ((FAST, "DOP853"), (REFERENCE, "DOP853")):
        rows = benchmark.of("duration", path=key[0])
        if rows:
            colour, marker, style = STYLE[key]
            growth.plot([row.value for row in rows], [row.cpu_s for row in rows], color=colour, ls=style,
                        marker=marker, label=f"{key[0]} DOP853")
            growth.plot([rows[0].value, rows[-1].value], [rows[0].cpu_s, rows[0].cpu_s * rows[-1].value / rows[0].value],
                        color=colour, lw=0.8, ls=":", label=f"{key[0]}: proportional to simulated time")
    growth.set_xscale("log")
    growth.set_yscale("log")
    growth.grid(which="major", alpha=0.35)
    growth.grid(which="minor", alpha=0.1)
    growth.set(xlabel="simulated time [s]", ylabel="CPU time of the run [s] (median)",
               title=f"{BENCH_SCENE}: cost against simulated time\n(DOP853, rtol {SCALING_RTOL:g})")
    if growth.lines:
        growth.legend(fontsize=9)
    figure.savefig(path, dpi=110)
    plt.close(figure)
