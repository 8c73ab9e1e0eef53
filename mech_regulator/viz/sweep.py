"""PNG picture of a sweep (matplotlib): the chosen metric over the grid and, for a direct governor, the
Vyshnegradsky diagram by simulation."""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (the backend must be chosen first)
import numpy as np  # noqa: E402

from mech_regulator.analysis.sweep import GridAxis  # noqa: E402
from mech_regulator.viz.plots import room_for_legend  # noqa: E402

VERDICT_STYLES = {
    True: dict(marker="o", color="tab:green", label="stable by simulation"),
    False: dict(marker="X", color="tab:red", label="unstable by simulation"),
}


def plot_sweep(
    rows: list[dict],
    axes: list[GridAxis],
    metric: str,
    title: str,
    path: Path,
    permitted_delta: float | None = None,
    labels: dict[str, str] | None = None,
) -> None:
    """One grid key: the metric against it (log axes for a geometric grid, the permitted delta as a line);
    two grid keys: a map of the metric over the grid; no grid (a list of scenes) or more keys: the metric per
    point. Points of a governed scene are marked stable / unstable by simulation. When the rows hold
    Vyshnegradsky's A and B (a direct governor), a second panel draws every point in the (A, B) plane with the
    boundary A B = 1 of the averaged linear model. labels: axis label per grid key (e.g. with its unit)."""
    labels = {axis.key: axis.key for axis in axes} | (labels or {})
    diagram = any(row.get("vyshnegradsky_A") is not None for row in rows)
    figure, panels = plt.subplots(
        1, 2 if diagram else 1, figsize=(14 if diagram else 8, 6), constrained_layout=True, squeeze=False
    )
    figure.suptitle(title)
    values = _column(rows, metric)
    if len(axes) == 1:
        _plot_against_key(panels[0, 0], rows, axes[0], labels[axes[0].key], metric, values, permitted_delta)
    elif len(axes) == 2:
        _plot_map(figure, panels[0, 0], rows, axes, [labels[axis.key] for axis in axes], metric, values)
    else:
        _plot_per_point(panels[0, 0], rows, axes, metric, values)
    if diagram:
        plot_vyshnegradsky(panels[0, 1], rows)
    figure.savefig(path, dpi=100)
    plt.close(figure)


def _column(rows: list[dict], name: str) -> np.ndarray:
    """A numeric column of the rows, NaN where a row has no number."""
    return np.array([float(row[name]) if isinstance(row.get(name), (int, float)) else math.nan for row in rows])


def _positions(axis: GridAxis, rows: list[dict]) -> tuple[np.ndarray, list[str] | None]:
    """The rows' values of a grid key as numbers, or as positions 0, 1, ... with tick labels for values that are
    not numbers (e.g. solver.method=RK45,DOP853)."""
    if all(isinstance(value, (int, float)) and not isinstance(value, bool) for value in axis.values):
        return np.array([float(row[axis.key]) for row in rows]), None
    return np.array([axis.values.index(row[axis.key]) for row in rows], dtype=float), list(axis.texts)


def _mark_verdicts(panel, x: np.ndarray, y: np.ndarray, rows: list[dict]) -> None:
    """Stable / unstable markers of the governed points (none for rows without a verdict)."""
    verdicts = np.array([row.get("stable_by_simulation") for row in rows], dtype=object)
    for verdict, style in VERDICT_STYLES.items():
        chosen = verdicts == verdict
        if np.any(chosen):
            panel.scatter(x[chosen], y[chosen], s=70, zorder=3, edgecolors="k", linewidths=0.6, **style)


def _plot_against_key(
    panel, rows, axis: GridAxis, label: str, metric: str, values: np.ndarray, permitted: float | None
) -> None:
    x, labels = _positions(axis, rows)
    panel.plot(x, values, color="tab:blue", lw=1.2, marker=".", ms=8, label=metric)
    _mark_verdicts(panel, x, values, rows)
    if axis.geometric:
        panel.set_xscale("log")
    finite = values[np.isfinite(values)]
    if axis.geometric and finite.size and np.all(finite > 0.0) and finite.max() > 10.0 * finite.min():
        panel.set_yscale("log")
    if metric == "delta" and permitted is not None:
        panel.axhline(permitted, color="tab:orange", lw=1.2, ls="--", label=f"permitted delta = {permitted:.4g}")
    if labels is not None:
        panel.set_xticks(range(len(labels)), labels)
    panel.set(xlabel=label, ylabel=metric, title=f"{metric} against {axis.key}")
    panel.grid(True, which="both", alpha=0.3)
    if panel.get_yscale() == "linear":
        room_for_legend(panel, 0.2)
    panel.legend(loc="best")


def _plot_map(figure, panel, rows, axes: list[GridAxis], labels: list[str], metric: str, values: np.ndarray) -> None:
    """pcolormesh of the metric over the two grid keys (rows in product order: the second key varies fastest)."""
    x, x_labels = _positions(axes[0], rows)
    y, y_labels = _positions(axes[1], rows)
    shape = (len(axes[0].values), len(axes[1].values))
    if len(rows) == shape[0] * shape[1]:
        mesh = panel.pcolormesh(
            x.reshape(shape), y.reshape(shape), values.reshape(shape), shading="nearest", cmap="viridis"
        )
    else:  # several scenes: one point per row
        mesh = panel.scatter(x, y, c=values, s=200, cmap="viridis")
    figure.colorbar(mesh, ax=panel, label=metric)
    _mark_verdicts(panel, x, y, rows)
    for axis, set_scale, ticks, set_ticks in (
        (axes[0], panel.set_xscale, x_labels, panel.set_xticks),
        (axes[1], panel.set_yscale, y_labels, panel.set_yticks),
    ):
        if axis.geometric:
            set_scale("log")
        if ticks is not None:
            set_ticks(range(len(ticks)), ticks)
    panel.set(xlabel=labels[0], ylabel=labels[1], title=f"{metric} over the grid")
    if any(row.get("stable_by_simulation") is not None for row in rows):
        panel.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2)


def _plot_per_point(panel, rows, axes: list[GridAxis], metric: str, values: np.ndarray) -> None:
    """The metric of each point in sweep order, labelled by its scene and grid values."""
    index = np.arange(len(rows))
    panel.plot(index, values, color="tab:blue", marker="o", lw=1.0, label=metric)
    _mark_verdicts(panel, index, values, rows)
    labels = [
        " ".join(
            [str(row["scene"])]
            + [
                f"{axis.key.split('.')[-1]}={row[axis.key]:.4g}"
                if isinstance(row[axis.key], float)
                else f"{row[axis.key]}"
                for axis in axes
            ]
        )
        for row in rows
    ]
    panel.set_xticks(
        index, labels, rotation=60 if len(rows) > 4 else 0, ha="right" if len(rows) > 4 else "center", fontsize="small"
    )
    panel.set(ylabel=metric, title=f"{metric} per point")
    panel.grid(True, alpha=0.3)
    panel.legend(loc="best")


def plot_vyshnegradsky(panel, rows: list[dict]) -> None:
    """The Vyshnegradsky diagram by simulation: each point at its (A, B) (log-log), marked stable / unstable by
    simulation, with the averaged linear model's boundary A B = 1 (stable above the hyperbola)."""
    a, b = _column(rows, "vyshnegradsky_A"), _column(rows, "vyshnegradsky_B")
    known = np.isfinite(a) & np.isfinite(b)
    low = min(a[known].min(), b[known].min(), 1.0) / 1.5
    high = max(a[known].max(), b[known].max(), 1.0) * 1.5
    line = np.geomspace(low, high, 200)
    panel.fill_between(line, 1.0 / line, high, color="tab:green", alpha=0.08)
    panel.fill_between(line, low, 1.0 / line, color="tab:red", alpha=0.08)
    panel.plot(line, 1.0 / line, color="k", lw=1.5, label="A B = 1 (averaged linear model)")
    _mark_verdicts(panel, a, b, rows)
    undecided = known & np.array([row.get("stable_by_simulation") is None for row in rows])
    if np.any(undecided):
        panel.scatter(a[undecided], b[undecided], s=50, color="0.6", label="no verdict (run too short or failed)")
    panel.set(
        xscale="log",
        yscale="log",
        xlim=(low, high),
        ylim=(low, high),
        xlabel="A = a2 / a0^(1/3)",
        ylabel="B = a1 / a0^(2/3)",
        title="Vyshnegradsky diagram by simulation",
    )
    panel.text(0.97, 0.97, "stable region", transform=panel.transAxes, ha="right", va="top", color="tab:green")
    panel.text(0.03, 0.03, "unstable region", transform=panel.transAxes, ha="left", va="bottom", color="tab:red")
    panel.grid(True, which="both", alpha=0.3)
    panel.legend(loc="upper left", framealpha=0.9)
