"""The output files of a command: their paths checked before any work (check_output_paths, output_folder) and their
estimated size against the free disk (check_free_space), each written after the work without losing the others when one fails (OutputWriter), and the lines naming them.

Light to import (the standard library only at module level): numpy, the model and the scene load inside the
functions that need them.
"""

from __future__ import annotations

import os
import shutil
import stat
import sys
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

from mech_regulator.cli.report.terminal import note, terminal_text
from mech_regulator.errors import EXIT_INACCURATE, EXIT_RUN_FAILED

if TYPE_CHECKING:
    pass


OUTPUT_KEYS = ("csv", "scene_out", "plot", "recording", "bag")


def wrote_lines(data: dict) -> list[str]:
    """'wrote PATH' for each file a command wrote: the OUTPUT_KEYS its answer holds, in that order."""
    return [f"wrote {data[key]}" for key in OUTPUT_KEYS if key in data]


def check_outputs(args, *others: Path | None) -> None:
    """Give args.plot a .png suffix and refuse, before any work, output paths (the plot and others) that cannot
    be written (check_output_paths)."""
    plot = getattr(args, "plot", None)
    if plot is not None and not plot.suffix:
        args.plot = plot = plot.with_suffix(".png")
    check_output_paths(*others, plot)


def check_output_paths(*paths: Path | None) -> None:
    """Refuse, before any work, output files that cannot be written: SceneError naming the first such path and why
    (output_refusal), or two outputs that are one file. None stands for an output not asked for."""
    from mech_regulator.scene import SceneError

    seen: set[str] = set()
    for path in paths:
        if path is None:
            continue
        problem = output_refusal(path)
        if problem is None and os.path.realpath(path) in seen:
            problem = "two of the command's outputs would be this one file"
        if problem is not None:
            raise SceneError(f"cannot write '{path}': {problem}")
        seen.add(os.path.realpath(path))


KERNEL_FOLDERS = (Path("/dev"), Path("/proc"), Path("/sys"))
"""The kernel's file systems (devices, processes, settings): no output is ever written there."""


LARGE_OUTPUTS_BYTES = 100e6
"""Outputs estimated to take more than this many bytes are announced before the work starts (check_free_space)."""

RECORDING_BYTES_PER_COLUMN = 12.0
"""[bytes] an upper-ish bound on the size of simulate's Rerun recording per sample and output column: measured 8.1
(lathe), 8.2 (shaper, whose mechanism's poses are recorded too), 10 (lathe co-simulated); docs/ros.md, "Outputs
against the free disk"."""

RUN_RECORDING_BYTES_PER_COLUMN = 32.0
"""[bytes] an upper-ish bound on the size of run's Rerun recording (the nodes' recorder) per exchange and output
column: measured 21 (engine_direct at 10 000 s)."""

RECORDING_LAYOUT_BYTES = 300e3
"""[bytes] a Rerun recording's part that does not grow with its samples (its layout, the mechanism's drawing):
measured 203 kB (lathe) and 259 kB (shaper)."""

BAG_BYTES_PER_COLUMN = 16.0
"""[bytes] an upper-ish bound on a rosbag2 (MCAP) bag's size per sample and output column: measured 12.2 (lathe) and
10.5 (shaper), besides some 13 kB of its own."""

SPOOL_BYTES_PER_EXCHANGE = 64.0
"""[bytes] an upper-ish bound on the recorder's spool per exchange: measured 56 (engine_direct)."""


def csv_bytes_per_row(columns: int, digits: int) -> float:
    """[bytes] an upper bound on a CSV row of `columns` numbers written with `digits` significant digits: each takes at
    most digits + 7 characters (a sign, a point, an exponent e-XXX) and its separator."""
    return columns * (digits + 8.0)


class OutputSize(NamedTuple):
    """An output's estimated size: its name as the messages quote it, the folder it goes in and its size [bytes]."""

    name: str
    folder: Path
    size: float


def output_sizes(
    columns: int,
    samples: float,
    csv: tuple[Path, int] | None,
    recording: tuple[Path, float] | None,
    bag: Path | None,
) -> list[OutputSize]:
    """The estimated size of each output asked for (None: not asked) holding `samples` rows of `columns` output
    columns: the CSV (its path and digits: csv_bytes_per_row), the recording (its path and bytes a sample and column,
    RECORDING_BYTES_PER_COLUMN or RUN_RECORDING_BYTES_PER_COLUMN, and RECORDING_LAYOUT_BYTES) and the bag folder
    (BAG_BYTES_PER_COLUMN)."""
    sizes = []
    if csv is not None:
        sizes.append(_output_size(csv[0], samples * csv_bytes_per_row(columns, csv[1])))
    if recording is not None:
        sizes.append(_output_size(recording[0], RECORDING_LAYOUT_BYTES + samples * columns * recording[1]))
    if bag is not None:
        sizes.append(_output_size(bag, samples * columns * BAG_BYTES_PER_COLUMN))
    return sizes


def _output_size(path: Path, size: float) -> OutputSize:
    """The OutputSize of the file (or bag folder) `path`, quoted, in the folder it goes in."""
    return OutputSize(f"'{path}'", Path(os.path.realpath(path)).parent, size)


def byte_text(size: float) -> str:
    """A size [bytes] as a person reads it: '420 MB', '8.1 GB' (powers of 1000)."""
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if size >= scale:
            return f"{size / scale:.2g} {unit}" if size < 10 * scale else f"{size / scale:.0f} {unit}"
    return f"{size:.0f} B"


def check_free_space(sizes: list[OutputSize], what: str, way_out: str) -> None:
    """Compare, before any work, the estimated sizes of a command's outputs (output_sizes) with the free space of
    their file systems (shutil.disk_usage; outputs on one file system add up): SceneError naming the outputs, their
    estimate, `what` they hold, the free space and `way_out` when they do not fit; when they fit and take more than
    LARGE_OUTPUTS_BYTES in all, one note saying so."""
    from mech_regulator.scene import SceneError

    systems: dict[int, list[OutputSize]] = {}
    for output in sizes:
        systems.setdefault(os.stat(output.folder).st_dev, []).append(output)
    for outputs in systems.values():
        needed = sum(output.size for output in outputs)
        free = shutil.disk_usage(outputs[0].folder).free
        if needed > free:
            raise SceneError(
                f"not enough free disk for {_named(outputs)}: some {byte_text(needed)} for {what}, and the file "
                f"system of '{outputs[0].folder}' has {byte_text(free)} free; expected {way_out}"
            )
    total = sum(output.size for output in sizes)
    if total > LARGE_OUTPUTS_BYTES:
        note(f"the outputs will take some {byte_text(total)} for {what}: {_named(sizes)}")


def _named(sizes: list[OutputSize]) -> str:
    """The outputs' names, each with its estimate."""
    return ", ".join(f"{output.name} ({byte_text(output.size)})" for output in sizes)


def output_refusal(path: Path) -> str | None:
    """Why the output file `path` cannot be written, or None: it is in KERNEL_FOLDERS or is not a regular file (a
    device, a pipe, a socket, a folder); its folder does not exist; or a first byte cannot be written (a read-only
    file system, no permission, a full disk), tried by writing one: a new file is made with it and removed, an
    existing one has its first byte written over with itself (an empty one gets one, taken away again)."""
    real = Path(os.path.realpath(path))  # where a symbolic link leads
    for kernel in KERNEL_FOLDERS:
        if real == kernel or kernel in real.parents:
            return (
                f"it is in {kernel}, the kernel's (devices, processes, settings): expected a regular file in a "
                "folder of yours"
            )
    try:
        mode = os.stat(real).st_mode
    except FileNotFoundError:
        mode = None
    except OSError as error:
        return error.strerror or str(error)
    if mode is not None and stat.S_ISDIR(mode):
        return "it is a folder"
    if mode is not None and not stat.S_ISREG(mode):
        return "it is a device, a pipe or a socket, not a regular file"
    if not real.parent.is_dir():
        return f"the folder '{path.parent}' does not exist"
    made = False
    try:
        if mode is None:
            with open(real, "xb") as probe:
                made = True
                probe.write(b"\0")
            real.unlink()
        else:
            with open(real, "r+b") as probe:
                first = probe.read(1)
                probe.seek(0)
                probe.write(first or b"\0")
                probe.flush()
                if not first:
                    probe.truncate(0)
    except OSError as error:
        if made:
            real.unlink(missing_ok=True)
        return error.strerror or str(error)
    return None


def output_folder(folder: Path, option: str = "--out") -> Path:
    """A command's output folder, made now if missing (with its parents), and checked to take files
    (output_refusal of a probe file in it): SceneError naming the option and the folder otherwise."""
    from mech_regulator.scene import SceneError

    if folder.exists() and not folder.is_dir():
        raise SceneError(f"{option} '{folder}': expected a folder, and it is a file or a device")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise SceneError(f"{option} '{folder}': cannot make the folder: {error.strerror or error}") from None
    problem = output_refusal(folder / f".mech-regulator-probe-{os.getpid()}")
    if problem is not None:
        raise SceneError(f"{option} '{folder}': cannot write in the folder: {problem}")
    return folder


class OutputWriter:
    """Writes a command's output files after its work, one by one: a write that fails then (a disk that fills up,
    an I/O error) is kept as one line and the other outputs are still written; the answer gets the key of each file
    written (wrote_lines)."""

    def __init__(self, answer: dict):
        self.answer = answer
        self.failures: list[str] = []

    def write(self, key: str, path: Path | None, write) -> None:
        """write(path), unless path is None; on success answer[key] = path."""
        if path is None:
            return
        try:
            write(path)
        except OSError as error:
            self.failures.append(f"writing '{path}' failed: {error.strerror or error}; that file is incomplete")
            return
        self.answer[key] = str(path)

    def exit_code(self, code: int) -> int:
        """Print each failure as a line on stderr; the command's exit code: EXIT_RUN_FAILED when a write failed and
        the command would otherwise have succeeded (0, or EXIT_INACCURATE of simulate --strict), else `code`."""
        for line in self.failures:
            print(f"mech-regulator: {terminal_text(line)}", file=sys.stderr)
        return EXIT_RUN_FAILED if self.failures and code in (0, EXIT_INACCURATE) else code


def bench_scenes_and_folder(scenes: str | None, out: Path, example: str) -> list[str] | None:
    """A benchmark's --scenes (comma-separated names; None: its default scenes) and its --out folder, made now and
    checked (output_folder): SceneError for an empty list (the message shows `example`) or a folder that cannot be
    made or written in."""
    from mech_regulator.scene import SceneError

    names = None if scenes is None else [name.strip() for name in scenes.split(",") if name.strip()]
    if names == []:
        raise SceneError(f"--scenes: expected scene names separated by commas, e.g. {example}")
    output_folder(out)
    return names
