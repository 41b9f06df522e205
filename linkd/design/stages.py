"""The progress display of a run (`linkd design`, `linkd export`): one line per stage with what
it found and its time.

On a terminal each running stage shows a spinner (with its progress, where the stage reports
it) and each finished one a line with its timing; anywhere else the display stays silent, and
the timings are still recorded for report.json.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager, nullcontext

from linkd.termination import check


class Stages:
    """Times named stages; shows them on a terminal when `show` (default: stdout is one)."""

    def __init__(self, show: bool | None = None) -> None:
        self.seconds: dict[str, float] = {}
        self.console = None
        self.status = None  # the running stage's spinner, on a terminal
        if sys.stdout.isatty() if show is None else show:
            from rich.console import Console

            self.console = Console()

    @contextmanager
    def stage(self, name: str, label: str) -> Iterator[Callable[[str], None]]:
        """Run a stage; the block may call the yielded function to say what the stage found.
        A termination the run swallowed on its way ends it here (`termination.check`)."""
        check()
        notes: list[str] = []
        start = time.perf_counter()
        spinner = self.console.status(label) if self.console else nullcontext()
        try:
            with spinner as self.status:
                yield notes.append
        finally:
            self.status = None
        seconds = time.perf_counter() - start
        self.seconds[name] = self.seconds.get(name, 0.0) + seconds
        if self.console:
            detail = "; ".join(notes)
            self.console.print(
                f"[green]✓[/] {name:<8} {detail:<56} [dim]{seconds:6.1f} s[/]", highlight=False
            )

    def progress(self, text: str) -> None:
        """Show how the running stage is getting on, in place of its label (on a terminal)."""
        if self.status is not None:
            self.status.update(text)

    def say(self, text: str) -> None:
        """A line on the terminal display (nothing elsewhere)."""
        if self.console:
            self.console.print(text, highlight=False)
