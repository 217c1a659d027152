"""One progress bar on stderr: realizations done, rate and ETA."""

import time

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    ProgressColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.text import Text


class _RateColumn(ProgressColumn):
    def render(self, task):
        speed = task.finished_speed or task.speed
        return Text("-- real/s" if not speed else f"{speed:,.0f} real/s")


class ProgressBar:
    """``with ProgressBar(total, "seed001-fig3") as bar: bar.advance(n)``.

    Disabled (``enabled=False``) it only counts. Output goes to stderr so that stdout stays
    machine-readable.
    """

    def __init__(self, total: int, description: str, enabled: bool = True):
        self.total = int(total)
        self.done = 0
        self.enabled = enabled
        self.t0 = time.perf_counter()
        self._progress = None
        if enabled:
            self._progress = Progress(
                TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                _RateColumn(), TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(),
                console=Console(stderr=True), transient=False,
            )
            self._task = self._progress.add_task(description, total=self.total)

    def __enter__(self):
        if self._progress is not None:
            self._progress.start()
        return self

    def advance(self, n: int):
        self.done += int(n)
        if self._progress is not None:
            self._progress.update(self._task, advance=int(n))

    def __exit__(self, *exc):
        if self._progress is not None:
            self._progress.stop()
        return False

    @property
    def elapsed_s(self) -> float:
        return time.perf_counter() - self.t0
