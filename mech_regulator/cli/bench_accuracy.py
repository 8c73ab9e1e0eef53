"""The `bench accuracy` command: the accuracy benchmark's runs, pictures and README."""

from __future__ import annotations

import sys

from mech_regulator.errors import EXIT_INTERRUPTED


def run_bench_accuracy(args) -> int:
    """bench accuracy: measure, then write runs.csv (also when interrupted), the PNGs, the recording and
    README.md into args.out."""
    import time

    from mech_regulator.bench.accuracy import run_benchmark, select_scenes
    from mech_regulator.bench.report import findings, markdown, write_runs_csv
    from mech_regulator.cli.report.outputs import bench_scenes_and_folder, check_output_paths
    from mech_regulator.scene import SceneError

    if args.jobs < 1:
        raise SceneError(f"--jobs {args.jobs}: expected at least 1 worker process")
    scenes = select_scenes(bench_scenes_and_folder(args.scenes, args.out, "startup,compressor"))
    check_output_paths(
        *(args.out / name for name in ("runs.csv", "README.md", "work_precision.rrd", "tolerance_proportionality.png"))
    )
    start = time.monotonic()
    benchmark = run_benchmark(scenes, args.quick, args.jobs, report=lambda line: print(line, flush=True))
    write_runs_csv(benchmark, args.out / "runs.csv")
    if benchmark.interrupted:
        print(f"mech-regulator: interrupted; the runs measured so far are in {args.out / 'runs.csv'}", file=sys.stderr)
        return EXIT_INTERRUPTED
    from mech_regulator.bench.effect_cost import effect_cost_section, effect_cost_table, measure_effect_costs
    from mech_regulator.viz.work_precision import write_pictures

    try:
        print("effect costs:", flush=True)
        costs = measure_effect_costs(1 if args.quick else 3, progress=lambda label: print(f"  {label}", flush=True))
        write_pictures(benchmark, args.out)
        (args.out / "README.md").write_text(
            markdown(benchmark, time.monotonic() - start) + effect_cost_section(costs), encoding="utf-8"
        )
    except KeyboardInterrupt:
        print(
            f"mech-regulator: interrupted while writing the pictures; every run is in {args.out / 'runs.csv'}",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED
    for result in benchmark.scenes:
        print(f"{result.bench.name}:", *findings(result), sep="\n")
    print("effect costs (DOP853, rtol 1e-8):", effect_cost_table(costs), sep="\n")
    print(
        f"wrote {args.out}: runs.csv, README.md, work_precision_<scene>.png, tolerance_proportionality.png, "
        f"work_precision.rrd ({time.monotonic() - start:.0f} s)"
    )
    return 0
