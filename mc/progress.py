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
    def __init__(self, unit="real"):
        super().__init__()
        self.unit = unit

    def render(self, task):
        speed = task.finished_speed or task.speed
        return Text(f"-- {self.unit}/s" if not speed else f"{speed:,.0f} {self.unit}/s")


class ProgressBar:
    """``with ProgressBar(total, "seed001-fig3") as bar: bar.advance(n)``.

    Disabled (``enabled=False``) it only counts. Output goes to stderr so that stdout stays
    machine-readable. ``rate_unit``: what the rate column counts per second ("real":
    realizations), None for no rate column (a few long items, e.g. ``reproduce``'s studies).
    """

    def __init__(self, total: int, description: str, enabled: bool = True,
                 rate_unit: str | None = "real"):
        self.total = int(total)
        self.done = 0
        self.enabled = enabled
        self.t0 = time.perf_counter()
        self._progress = None
        if enabled:
            columns = [TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn()]
            if rate_unit is not None:
                columns.append(_RateColumn(rate_unit))
            columns += [TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn()]
            self._progress = Progress(*columns, console=Console(stderr=True), transient=False)
            self._task = self._progress.add_task(description, total=self.total)

    def __enter__(self):
        if self._progress is not None:
            self._progress.start()
        return self

    def advance(self, n: int):
        """Count ``n`` more realizations done."""
        self.done += int(n)
        if self._progress is not None:
            self._progress.update(self._task, advance=int(n))

    def __exit__(self, *exc):
        if self._progress is not None:
            self._progress.stop()
        return False

    @property
    def elapsed_s(self) -> float:
        """Wall-clock seconds since the bar was made."""
        return time.perf_counter() - self.t0


class _CellsColumn(ProgressColumn):
    def render(self, task):
        return Text(f"{task.fields.get('cells_done', 0):,}/{task.fields.get('cells', 0):,} cells")


class SweepProgress:
    """One bar for a whole sweep: cells done / total, realizations per second and ETA (both
    from the realizations still to compute: chunks reused by a resume count as done cells but
    not towards the rate), then a final line. Output goes to stderr.

    ``with SweepProgress(cells, todo_realizations, "label") as bar:
    bar.advance(n, cells=k); bar.final_line("...")``. Disabled, it only counts.
    """

    def __init__(self, cells: int, realizations: int, description: str, enabled: bool = True):
        self.cells = int(cells)
        self.cells_finished = 0
        self.realizations = int(realizations)
        self.done = 0
        self.enabled = enabled
        self.t0 = time.perf_counter()
        self._final = None
        self._console = Console(stderr=True)
        self._progress = None
        if enabled:
            self._progress = Progress(
                TextColumn("{task.description}"), BarColumn(), _CellsColumn(), _RateColumn(),
                TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(),
                console=self._console, transient=False,
            )
            self._task = self._progress.add_task(description, total=max(self.realizations, 1),
                                                 cells=self.cells, cells_done=0)

    def __enter__(self):
        if self._progress is not None:
            self._progress.start()
        return self

    def cells_done(self, n: int):
        """Mark ``n`` more cells as finished (e.g. those a resume found complete)."""
        self.cells_finished += int(n)
        if self._progress is not None:
            self._progress.update(self._task, cells_done=self.cells_finished)

    def advance(self, realizations: int, cells: int = 0):
        """Count ``realizations`` more computed and ``cells`` more finished."""
        self.done += int(realizations)
        self.cells_finished += int(cells)
        if self._progress is not None:
            self._progress.update(self._task, advance=int(realizations),
                                  cells_done=self.cells_finished)

    def final_line(self, text: str):
        """Printed after the bar closes (only when enabled)."""
        self._final = text

    def __exit__(self, *exc):
        if self._progress is not None:
            if self.realizations == 0:  # everything reused: show a full bar
                self._progress.update(self._task, completed=1)
            self._progress.stop()
            if self._final is not None and exc[0] is None:
                self._console.print(self._final, highlight=False, soft_wrap=True)
        return False

    @property
    def elapsed_s(self) -> float:
        """Wall-clock seconds since the bar was made."""
        return time.perf_counter() - self.t0
