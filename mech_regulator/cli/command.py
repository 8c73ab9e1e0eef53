"""Running the command line in this process: its modules imported inside the call, so that a Ctrl-C while they
load ends as quietly as one later does."""

from __future__ import annotations

import sys
from pathlib import Path

from mech_regulator.errors import EXIT_INTERRUPTED


def run_command(argv: list[str]) -> int:
    """The command line (cli.main.main) run on argv in this process, imported here so that a Ctrl-C while its
    modules load ends quietly with exit code 130, as a Ctrl-C later does; `run` then still leaves its summary
    (summary_before_start: nothing simulated)."""
    try:
        from mech_regulator.cli.main import main

        return main(argv)
    except KeyboardInterrupt:
        print("mech-regulator: interrupted", file=sys.stderr)
        if argv[:1] == ["run"]:
            written = summary_before_start(argv)
            if written is not None:
                print(f"mech-regulator: nothing was simulated; wrote {written}", file=sys.stderr)
        return EXIT_INTERRUPTED


def summary_before_start(argv: list[str]) -> Path | None:
    """`run`'s summary when Ctrl-C came before main_job could start the nodes (while the command's modules or the
    scene loaded; argv: the command line, 'run' first): status interrupted, nothing simulated, written next to the
    recording `--out` names (default: runs/<scene argument>-<time>.rrd), and its path; None when argv does not parse
    or the file cannot be written (the interrupt is then all there is to say)."""
    from mech_regulator.cli.parser import build_parser
    from mech_regulator.cli.report.data import to_json
    from mech_regulator.nodes.launch import NOTHING_SIMULATED
    from mech_regulator.nodes.outputs import default_recording

    try:
        args = build_parser().parse_args(argv)
        output = args.out or default_recording(Path(args.scene).stem)
        summary_path = output.with_suffix(".json")
        output.parent.mkdir(parents=True, exist_ok=True)
        summary_path.write_text(
            to_json(
                {
                    "scene": args.scene,
                    "status": "interrupted",
                    "message": NOTHING_SIMULATED,
                    "samples": 0,
                    "t_end": 0.0,
                    "recording": None,
                }
            )
        )
    except (SystemExit, OSError):
        return None
    return summary_path
