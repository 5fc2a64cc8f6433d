"""Progress of long jobs: a ``report`` is a function that takes one line.

:func:`print_now` prints each line at once; :func:`quiet` drops them.
:class:`MatrixProgress` reports the matrix: finished, failed and remaining
runs and the time left.
"""

from __future__ import annotations

import sys
import time
from typing import Callable

Report = Callable[[str], None]


def print_now(line: str) -> None:
    """A ``report`` that prints each line at once."""
    print(line, flush=True)


def quiet(line: str) -> None:
    """A ``report`` that prints nothing."""


class MatrixProgress:
    """Progress of the matrix: finished, failed and remaining runs and the time left.

    With :func:`print_now` on a terminal this is a tqdm bar, with one line per
    finished run printed above it; otherwise (a log file, or another
    ``report``) each finished run gives one line that starts with a text bar.
    """

    def __init__(self, total: int, skipped: int, workers: int, report: Report | None):
        self.total, self.skipped, self.workers, self.report = total, skipped, workers, report
        self.finished = self.failed = 0
        self.start = time.monotonic()
        if report and skipped:
            report(f"resuming: {skipped} run(s) already have records")
        if report:
            report(f"{total} run(s) to do on {workers} worker(s)")
        self.bar = None
        if report is print_now and total and sys.stderr.isatty():
            from tqdm import tqdm

            self.bar = tqdm(total=total, unit="run", dynamic_ncols=True, postfix={"failed": 0})

    def done(self, ok: bool, what: str) -> None:
        """Count one finished run, described by ``what``."""
        self.finished += 1
        self.failed += not ok
        if not self.report:
            return
        if self.bar is not None:
            self.bar.write(what)
            self.bar.set_postfix(failed=self.failed, refresh=False)
            self.bar.update(1)
            return
        elapsed = time.monotonic() - self.start
        left = self.total - self.finished
        eta = elapsed / self.finished * left
        self.report(f"{text_bar(self.finished, self.total)} {self.finished}/{self.total} done, {self.failed} not ok, "
                    f"{left} left, ~{fmt_time(eta)} to go | {what}")

    def summary(self) -> None:
        if self.bar is not None:
            self.bar.close()
        if self.report and self.total:
            self.report(f"matrix done in {fmt_time(time.monotonic() - self.start)}: {self.finished - self.failed} ok, {self.failed} not ok")


def text_bar(done: int, total: int, width: int = 20) -> str:
    filled = round(width * done / total) if total else width
    return "[" + "#" * filled + "." * (width - filled) + "]"


def fmt_time(seconds: float) -> str:
    seconds = int(round(seconds))
    if seconds < 60:
        return f"{seconds}s"
    if seconds < 3600:
        return f"{seconds // 60}m{seconds % 60:02d}s"
    return f"{seconds // 3600}h{seconds % 3600 // 60:02d}m"
