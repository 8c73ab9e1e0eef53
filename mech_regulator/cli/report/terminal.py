"""Text for the terminal: scene text made safe to show (terminal_text), a command's notes, and the progress of
long work (a tqdm bar on a terminal, plain lines in a log).

Light to import (the standard library only at module level): numpy, the model and the scene load inside the
functions that need them.
"""

from __future__ import annotations

import math
import os
import re
import sys
import time
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    pass


_UNSHOWABLE = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f\u061c\u200e\u200f\u2028\u2029\u202a-\u202e\u2066-\u2069]")
"""Characters a terminal would act on instead of showing: control characters but newline and tab (ESC starts an
escape sequence, BEL rings, CR returns to the line's start) and the bidirectional marks, embeddings, overrides and
isolates (U+200E, U+200F, U+061C, U+202A-U+202E, U+2066-U+2069: they reorder what follows them), and the line and
paragraph separators."""


def terminal_text(text: str) -> str:
    """Text from a scene (its name, a message quoting it) as the terminal may show it: each character of _UNSHOWABLE
    written as Python writes it in a string literal (ESC as \\x1b, U+202E as \\u202e), newlines and tabs kept."""
    return _UNSHOWABLE.sub(lambda match: repr(match.group())[1:-1], text)


def note(line: str) -> None:
    """A one-line note of a command on stderr (e.g. which path a run takes and why)."""
    print(f"mech-regulator: {terminal_text(line)}", file=sys.stderr)


PROGRESS_INTERVAL_VARIABLE = "MECH_REGULATOR_PROGRESS_INTERVAL"


ETA_AFTER = 1.0  # [s] of wall time the work has run before a progress line gives an ETA (or ETA_SHARE of it done)
ETA_SHARE = 0.01  # [-] of the total done before a progress line gives an ETA (or ETA_AFTER s run)
PROGRESS_INTERVAL = 3.0  # [s] of wall time between two progress lines in a log (not a terminal), by default


START_UP_SHOWN = 0.05  # [s] of wall time before the first update from which the final line names the start-up


def progress_bar(
    total: float | None,
    quiet: bool,
    label: str = "simulating",
    quantity: str | None = "t",
    unit: str = "s",
    started: float | None = None,
):
    """The progress of long work on stderr, as a context manager with tqdm's `update(amount)` and `n`: nothing
    when quiet; tqdm's bar on a terminal; in a log, a pipe or a notebook (stderr not a terminal, where tqdm would
    show nothing useful), a plain line every few seconds of wall time (ProgressLines). total: the amount to do,
    simulated seconds by default (None: unknown, a count); label names the work, quantity the amount
    ('t = 3.2 / 10 s'; None: '3.2 / 10 s'), unit its unit, started when the work was asked for (time.monotonic()
    [s]; None: now)."""
    label = terminal_text(label)
    if quiet or not _is_terminal(sys.stderr):
        return ProgressLines(total, label, quantity, unit, progress_interval(), enabled=not quiet, started=started)
    from tqdm import tqdm

    amount = f"{quantity} = " if quantity else ""
    if total is None:
        return tqdm(desc=label, file=sys.stderr, bar_format=f"{{desc}}: {{n:.4g}} {unit} [{{elapsed}}]")
    return tqdm(
        total=total,
        desc=label,
        file=sys.stderr,
        bar_format=f"{{l_bar}}{{bar}}| {amount}{{n:.3g}}/{{total:.3g}} {unit} [{{elapsed}}<{{remaining}}]",
    )


def progress_interval() -> float:
    """Wall time [s] between two progress lines in a log: $MECH_REGULATOR_PROGRESS_INTERVAL when it is a number
    >= 0, else PROGRESS_INTERVAL."""
    try:
        interval = float(os.environ.get(PROGRESS_INTERVAL_VARIABLE, ""))
    except ValueError:
        return PROGRESS_INTERVAL
    return interval if math.isfinite(interval) and interval >= 0.0 else PROGRESS_INTERVAL


def _is_terminal(stream) -> bool:
    try:
        return stream.isatty()
    except (AttributeError, ValueError):  # no isatty, or closed
        return False


class ProgressLines:
    """Progress as plain lines on stderr for a log: after `interval` s of wall time since the last line, the next
    update prints `simulating lathe: t = 3.2 / 10 s (32 %), 4.1 s elapsed, ETA 8.7 s`; at the end `simulating
    lathe: done: t = 10 / 10 s in 12.3 s` (`stopped at` when the work ended short of its total), with `; start-up
    3.1 s` when the work began that long after `started`. The times are the work's own: from its start (the
    last update that still reported nothing done: the nodes' first diagnostics come as their exchanges start; else
    the bar's creation) to the latest update, so that a start-up (the nodes' discovery) is neither in the ETA (the
    time so far scaled by what is left) nor in the duration, which is then the summary's (the nodes' wall time over
    the exchanges; the start-up from the command). Work that ends within one interval prints nothing. The same
    interface as the tqdm bar the command line uses (update, n, set_description_str, close, a context manager);
    silent unless enabled (--quiet). No thread: a line comes with an update."""

    def __init__(
        self,
        total: float | None,
        label: str,
        quantity: str | None,
        unit: str,
        interval: float,
        enabled: bool = True,
        file=None,
        clock=time.monotonic,
        started: float | None = None,
    ):
        self.total, self.label, self.quantity, self.unit = total, label, quantity, unit
        self.interval, self.enabled, self.file, self.clock = interval, enabled, file, clock
        self.n = 0.0
        self.stage = ""
        self.start = self.last = self.began = self.latest = clock()  # began: the work's start; latest: its update
        self.started = self.start if started is None else started  # when the work was asked for
        self.printed = False
        self.closed = False

    def __enter__(self) -> ProgressLines:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def update(self, amount: float = 1) -> None:
        now = self.latest = self.clock()
        self.n += amount
        if self.n == 0.0:
            self.began = now  # nothing done yet: the work has not begun
        if self.enabled and now - self.last >= self.interval:
            self.last = now
            elapsed = now - self.began
            self._print(
                f"{self._label()}: {self._amount()}{self._share()}, {_duration(elapsed)} elapsed" + self._eta(elapsed)
            )

    def set_description_str(self, text: str, refresh: bool = False) -> None:
        """The current stage of the work (flywheel: the flywheel being simulated), shown after the label."""
        self.stage = text

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        if self.enabled and (self.printed or self.clock() - self.start >= self.interval):
            short = self.total is not None and self.n < self.total * (1.0 - 1e-9)
            start_up = self.began - self.started
            self._print(
                f"{self.label}: {'stopped at' if short else 'done:'} {self._amount()} "
                f"{'after' if short else 'in'} {_duration(self.latest - self.began)}"
                + (f"; start-up {_duration(start_up)}" if start_up >= START_UP_SHOWN else "")
            )

    def _label(self) -> str:
        return f"{self.label} ({self.stage})" if self.stage else self.label

    def _amount(self) -> str:
        amount = f"{self.quantity} = " if self.quantity else ""
        if self.total is None:
            return f"{amount}{self.n:.4g} {self.unit}"
        return f"{amount}{_progress_number(self.n)} / {_progress_number(self.total)} {self.unit}"

    def _share(self) -> str:
        return f" ({100.0 * self.n / self.total:.0f} %)" if self.total else ""

    def _eta(self, elapsed: float) -> str:
        """', ETA ...' at the pace of the work so far ('' without a total); unknown until the work has done ETA_SHARE
        of the total or run ETA_AFTER s (a pace read off its first steps, first calls included, can be off by orders
        of magnitude)."""
        if not self.total:
            return ""
        if self.n <= 0.0 or (self.n < ETA_SHARE * self.total and elapsed < ETA_AFTER):
            return ", ETA unknown"
        return f", ETA {_duration(max(elapsed * (self.total - self.n) / self.n, 0.0))}"

    def _print(self, line: str) -> None:
        self.printed = True
        print(line, file=self.file or sys.stderr, flush=True)


def _progress_number(value: float) -> str:
    """An amount for a progress line: 3 significant digits, and every digit of its integer part ('42.7', '3600',
    '12346' rather than '3.6e+03' and '1.23e+04'), so that a long run's lines tell its pace to the second."""
    return f"{value:.{max(3, len(f'{abs(value):.0f}'))}g}"


def _duration(seconds: float) -> str:
    """Wall time for a progress line: '4.1 s', '2 min 05 s', '1 h 02 min'."""
    if seconds < 99.95:
        return f"{seconds:.1f} s"
    minutes, rest = divmod(round(seconds), 60)
    if minutes < 60:
        return f"{minutes} min {rest:02d} s"
    return f"{minutes // 60} h {minutes % 60:02d} min"
