"""What the work–precision benchmark found, as numbers and text: the CSV of every run, the findings per
scene (cheapest method to an accuracy, cost of one more digit, tolerance proportionality, observed
order of the fixed-step methods) and the markdown report (docs/accuracy/README.md)."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from mech_regulator.bench.accuracy import (
    ADAPTIVE,
    CHECK_METHOD,
    COSIM,
    COSIM_RTOL,
    GRID_RATE,
    IMPLICIT_TIGHTEST,
    MAX_REPEATS,
    METHODS,
    REFERENCE_METHOD,
    REFERENCE_RTOL,
    REPEAT_BUDGET_S,
    Benchmark,
    Run,
    SceneResult,
    error_kind,
    power_of_ten,
)

TARGETS = (1e-4, 1e-7, 1e-10)  # headline errors at which the cheapest method is named
FINEST_POINTS = 4  # the cost of one more digit is fitted over a method's finest resolved runs
FIXED_STEP = ("RK4", "energy", COSIM)
CSV_COLUMNS = (
    "scene",
    "method",
    "parameter",
    "value",
    "label",
    "atol",
    "status",
    "cpu_s",
    "repeats",
    "nfev",
    "steps",
    "error",
    "reference_error",
    "below_reference",
)

# ---------------------------------------------------------------------------------------------
# CSV


def state_columns(benchmark: Benchmark) -> list[str]:
    """Error columns of the states of all scenes, in order of appearance: <state>_rms_<kind> and
    <state>_end_<kind>, kind 'rad' (absolute) or 'rel' (relative, see accuracy.error_scale)."""
    names = dict.fromkeys(name for result in benchmark.scenes for name in result.state_names)
    return [f"{name}_{which}_{error_kind(name)}" for name in names for which in ("rms", "end")]


def write_runs_csv(benchmark: Benchmark, path: Path) -> None:
    """One row per run: scene, method, the setting swept (parameter, value [-, s or deg], label), atol of
    the adaptive methods, status, median CPU time [s] and repeats, RHS evaluations (empty: not reported),
    steps, the headline error (omega RMS relative to max |omega_ref|), the reference's own error and
    whether the run lies below it, the errors per state (see state_columns) and the failure message."""
    columns = state_columns(benchmark)
    with open(path, "w", newline="", encoding="utf-8") as stream:
        writer = csv.writer(stream)
        writer.writerow([*CSV_COLUMNS, *columns, "message"])
        for result in benchmark.scenes:
            scale = result.bench.state_scale
            for run in result.runs:
                setting = run.setting
                errors = {
                    f"{name}_{which}_{error_kind(name)}": pair[i]
                    for name, pair in run.errors.items()
                    for i, which in enumerate(("rms", "end"))
                }
                writer.writerow(
                    [
                        result.bench.name,
                        setting.method,
                        setting.parameter,
                        f"{setting.value:g}",
                        setting.label,
                        _number(setting.value * scale if setting.method in ADAPTIVE else None),
                        run.status,
                        _number(run.cpu),
                        run.repeats,
                        "" if run.nfev is None else run.nfev,
                        run.steps,
                        _number(run.error),
                        _number(result.reference_error),
                        int(result.below_reference(run)),
                        *(_number(errors.get(column)) for column in columns),
                        run.message,
                    ]
                )


def _number(value: float | None) -> str:
    """A number with 6 significant digits; empty for none or nan."""
    return "" if value is None or not math.isfinite(value) else f"{value:.6g}"


# ---------------------------------------------------------------------------------------------
# Findings


def resolved(result: SceneResult, method: str) -> list[Run]:
    """A method's completed runs whose error lies at or above the reference's own error, loosest first."""
    return [run for run in result.runs_of(method) if not result.below_reference(run)]


def cheapest(result: SceneResult, target: float) -> Run | None:
    """The run of least CPU time whose headline error is at most target (None if no run reaches it, or
    the reference cannot tell: target below the reference's own error)."""
    if target < result.reference_error:
        return None
    runs = [run for method in METHODS for run in result.runs_of(method) if run.error <= target]
    return min(runs, key=lambda run: run.cpu, default=None)


def cost_per_digit(result: SceneResult, method: str) -> float | None:
    """Factor of CPU time per tenfold smaller headline error, fitted (least squares in log-log) over the
    method's FINEST_POINTS finest resolved runs; None with fewer than 3 or errors that do not fall."""
    runs = resolved(result, method)[-FINEST_POINTS:]
    if len(runs) < 3:
        return None
    digits = -np.log10([run.error for run in runs])
    if np.ptp(digits) < 0.5:
        return None
    slope = np.polyfit(digits, np.log10([run.cpu for run in runs]), 1)[0]
    return float(10.0**slope)


def observed_order(result: SceneResult, method: str) -> float | None:
    """Order p of a fixed-step method, error ~ step^p, fitted (least squares in log-log) over its resolved
    runs; None with fewer than 3."""
    runs = resolved(result, method)
    if len(runs) < 3:
        return None
    return float(np.polyfit(np.log10([run.setting.value for run in runs]), np.log10([run.error for run in runs]), 1)[0])


def proportionality(result: SceneResult, method: str) -> tuple[float, float, int] | None:
    """Tolerance proportionality of an adaptive method over its resolved runs: the smallest and largest
    achieved error / requested rtol, and how many times the error grew although rtol was tightened."""
    runs = resolved(result, method)
    if not runs:
        return None
    ratios = [run.error / run.setting.value for run in runs]
    reversals = sum(later.error > earlier.error for earlier, later in zip(runs, runs[1:]))
    return min(ratios), max(ratios), reversals


def describe_run(run: Run | None) -> str:
    """'DOP853 1e-8 (12.3 ms)' or '—'."""
    if run is None:
        return "—"
    return f"{run.setting.method} {run.setting.label} ({_duration(run.cpu)})"


def _duration(seconds: float) -> str:
    """A CPU time in ms below a second, else in s."""
    return f"{seconds * 1e3:.3g} ms" if seconds < 1.0 else f"{seconds:.3g} s"


def digit_costs(result: SceneResult) -> dict[str, float]:
    """Cost of one more digit per method with enough resolved runs, cheapest first."""
    factors = {method: cost_per_digit(result, method) for method in METHODS}
    return dict(
        sorted(((method, factor) for method, factor in factors.items() if factor is not None), key=lambda item: item[1])
    )


def findings(result: SceneResult) -> list[str]:
    """What a scene's runs show, as markdown bullet lines."""
    lines = []
    reference = result.reference_error
    if result.bench.closed_form is not None:
        lines.append("The reference is exact (closed form): every error is the method's own.")
    elif math.isfinite(reference):
        lines.append(
            f"The reference ({result.reference}) agrees with its check to {reference:.1g} (omega RMS, "
            "relative): errors below that are not resolved and are drawn hollow."
        )
    for target in TARGETS:
        if target < reference:
            lines.append(f"Error {power_of_ten(target)}: below the reference's own error, not measurable here.")
            continue
        best = cheapest(result, target)
        lines.append(
            f"Cheapest to an error of {power_of_ten(target)}: {describe_run(best)}."
            if best is not None
            else f"No run reached an error of {power_of_ten(target)}."
        )
    factors = digit_costs(result)
    if factors:
        lines.append(
            "One more digit (10x smaller error) costs, in CPU time, over each method's finest resolved "
            "runs: " + ", ".join(f"{method} x{factor:.2g}" for method, factor in factors.items()) + "."
        )
    orders = {method: observed_order(result, method) for method in FIXED_STEP}
    orders = {method: order for method, order in orders.items() if order is not None}
    if orders:
        lines.append(
            "Observed order of the fixed-step methods (error ~ step^p): "
            + ", ".join(f"{method} p = {order:.2g}" for method, order in orders.items())
            + "."
        )
    spans = {method: span for method in ADAPTIVE if (span := proportionality(result, method)) is not None}
    if spans:
        lines.append(
            "Tolerance proportionality, achieved error / requested rtol: "
            + ", ".join(
                f"{method} {low:.2g}–{high:.2g}"
                + (f" ({reversals} reversal{'s' * (reversals > 1)})" if reversals else "")
                for method, (low, high, reversals) in spans.items()
            )
            + "."
        )
    flagged = [run for run in result.runs if result.below_reference(run)]
    if flagged:
        lines.append(
            f"{len(flagged)} run{'s lie' if len(flagged) > 1 else ' lies'} below the reference's own error: "
            + ", ".join(f"{run.setting.method} {run.setting.label}" for run in flagged)
            + "."
        )
    failed = [run for run in result.runs if run.status != "complete"]
    if failed:
        lines.append(
            "Failed: " + "; ".join(f"{run.setting.method} {run.setting.label}: {run.message}" for run in failed) + "."
        )
    return [f"- {line}" for line in lines]


# ---------------------------------------------------------------------------------------------
# Markdown


def markdown(benchmark: Benchmark, wall_seconds: float) -> str:
    """docs/accuracy/README.md: how the benchmark measures, the key findings, the tolerance
    proportionality picture and, per scene, its picture, findings and the table of its runs."""
    env = benchmark.environment
    mode = "`--quick` (few points, tiny durations)" if benchmark.quick else "default settings"
    lines = [
        "# Work–precision benchmark",
        "",
        f"Generated by `mech-regulator bench accuracy` ({mode}) on {env['date']}: {env['processor']}, Python "
        f"{env['python']}, numpy {env['numpy']}, scipy {env['scipy']}, {env['jobs']} worker processes, "
        f"{wall_seconds:.0f} s wall time. Every run is in [runs.csv](runs.csv); the same curves are in the Rerun "
        "recording [work_precision.rrd](work_precision.rrd) (open it with `rerun work_precision.rrd` in this folder).",
        "",
        "## How it is measured",
        "",
        "- Each scene is integrated by every method over a sweep of its accuracy setting: the requested "
        "tolerance rtol of scipy's adaptive methods (atol = rtol x the scene's state scale; Radau and BDF down to "
        f"{power_of_ten(IMPLICIT_TIGHTEST)}), the step of RK4, the crank-angle step of the energy method (no governor, "
        "no coupling) and the exchange step of the ROS nodes' lockstep co-simulation (governed scenes; its machine "
        f"and governor are integrated by DOP853 at rtol {power_of_ten(COSIM_RTOL)}, so its error is the hold's).",
        "- Cost: CPU time of the integration alone (`time.process_time`, median of repeats: a run is repeated until "
        f"about {REPEAT_BUDGET_S:g} s of CPU time is spent, at most {MAX_REPEATS} times), right-hand-side "
        "evaluations and steps. The co-simulation reports no evaluations (`cosimulate` returns no solver "
        "statistics); its steps are exchange steps.",
        f"- Reference: the closed form where there is one, else {REFERENCE_METHOD} at rtol "
        f"{power_of_ten(REFERENCE_RTOL)}, checked by {CHECK_METHOD}; their disagreement is the reference's own "
        "error, and a run whose error lies below it is flagged (hollow markers, `below_reference` in the CSV).",
        f"- Achieved error, per state, at the end point and as RMS over a {GRID_RATE / 1e3:g} kHz time grid of the "
        "dense output (the co-simulation over its exchange times): speeds relative to max |omega_ref|, the crank "
        "angle phi absolute in rad (it grows, so it is never divided by), governor states and a coupling's twist "
        "relative to their range over the run. The headline error, on the pictures' x axis, is omega's RMS error.",
        "",
        "## Key findings",
        "",
        "| scene | reference's own error | "
        + " | ".join(f"cheapest to {power_of_ten(target)}" for target in TARGETS)
        + " | one more digit costs (CPU, cheapest three) |",
        "| --- | ---: | " + " | ".join("---" for _ in TARGETS) + " | --- |",
    ]
    for result in benchmark.scenes:
        cells = []
        for target in TARGETS:
            cells.append(
                "below the reference" if target < result.reference_error else describe_run(cheapest(result, target))
            )
        factors = ", ".join(f"{method} x{factor:.2g}" for method, factor in list(digit_costs(result).items())[:3])
        reference = "exact" if result.bench.closed_form is not None else f"{result.reference_error:.1g}"
        lines.append(
            f"| [{result.bench.name}](#{result.bench.name}) | {reference} | "
            + " | ".join(cells)
            + f" | {factors or '—'} |"
        )
    lines += [
        "",
        "## Tolerance proportionality",
        "",
        "Achieved error against the requested rtol, per adaptive method: on the dashed diagonal the error is "
        "what was asked for; below the dotted line (the reference's own error) nothing is resolved.",
        "",
        "![achieved error against requested rtol](tolerance_proportionality.png)",
        "",
    ]
    for result in benchmark.scenes:
        lines += _scene_section(result)
    return "\n".join(lines) + "\n"


def _scene_section(result: SceneResult) -> list[str]:
    bench = result.bench
    others = [name for name in result.state_names if name not in ("phi", "omega")]
    lines = [
        f"## {bench.name}",
        "",
        f"{result.description}",
        "",
        f"Benchmark run: {bench.what}; reference: {result.reference}; states {', '.join(result.state_names)}.",
        "",
        f"![work-precision diagram of {bench.name}](work_precision_{bench.name}.png)",
        "",
        *findings(result),
        "",
        "| method | setting | omega RMS [-] | omega end [-] | phi end [rad] |"
        + (f" {', '.join(others)}: worst RMS [-] |" if others else "")
        + " CPU [ms] | RHS evaluations | steps | |",
        "| --- | ---: | ---: | ---: | ---: |" + (" ---: |" if others else "") + " ---: | ---: | ---: | --- |",
    ]
    for run in result.runs:
        errors = run.errors
        note = (
            "below the reference's error"
            if result.below_reference(run)
            else run.status
            if run.status != "complete"
            else ""
        )
        worst = max((errors[name][0] for name in others if name in errors), default=math.nan)
        lines.append(
            f"| {run.setting.method} | {run.setting.label} | {_cell(errors.get('omega', (math.nan,))[0])} | "
            f"{_cell(errors.get('omega', (0, math.nan))[1])} | {_cell(errors.get('phi', (0, math.nan))[1])} |"
            + (f" {_cell(worst)} |" if others else "")
            + f" {_milliseconds(run.cpu)} | {'' if run.nfev is None else run.nfev} | {run.steps} | {note} |"
        )
    return lines + [""]


def _milliseconds(seconds: float) -> str:
    """A CPU time in ms, 3 significant digits below 1000 ms, whole ms above."""
    milliseconds = seconds * 1e3
    return f"{milliseconds:.3g}" if milliseconds < 1e3 else f"{milliseconds:.0f}"


def _cell(value: float) -> str:
    return f"{value:.2e}" if math.isfinite(value) else "—"


__all__ = ["cheapest", "cost_per_digit", "findings", "markdown", "observed_order", "proportionality", "write_runs_csv"]
