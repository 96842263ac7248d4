"""The CLI's progress bar: a rich bar on stderr when stderr is a terminal, else nothing.

``with progress_bar(args, "meshing") as progress: engine_call(..., progress=progress)``
gives the engine a :data:`ctui.engine.core.progress.Progress` callback. Nothing is drawn
with ``--json``, when stderr is not a terminal, or with ``CTUI_NO_PROGRESS=1``; the bar
appears only after ``delay`` seconds so fast commands print nothing extra.
"""

from __future__ import annotations

import contextlib
import os
import sys
import time
from typing import Any, Iterator


def wants_bar(args: Any = None) -> bool:
    if getattr(args, "json", False) or os.environ.get("CTUI_NO_PROGRESS"):
        return False
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


@contextlib.contextmanager
def progress_bar(args: Any, description: str, *, delay: float = 0.3) -> Iterator[Any]:
    """Yield a ``progress(done, total, message="")`` callback (None when no bar is wanted)."""
    if not wants_bar(args):
        yield None
        return
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    console = Console(file=sys.stderr)
    bar = Progress(TextColumn("[bold]{task.description}"), BarColumn(), TextColumn("{task.percentage:>3.0f}%"),
                   TimeElapsedColumn(), TimeRemainingColumn(), TextColumn("{task.fields[note]}"),
                   console=console, transient=True)
    task = bar.add_task(description, total=1.0, note="")
    from ctui.engine.core.safetext import printable  # object names in the notes came from files
    delay = float(os.environ.get("CTUI_PROGRESS_DELAY", delay))  # tests: 0 draws at the first report
    t0 = time.monotonic()
    started = False

    def callback(done: float, total: float, message: str = "") -> None:
        nonlocal started
        if not started and time.monotonic() - t0 >= delay:
            bar.start()
            started = True
        frac = (float(done) / float(total)) if total else 0.0
        bar.update(task, completed=min(max(frac, 0.0), 1.0), note=printable(message or "").replace("[", "\\["))

    try:
        yield callback
    finally:
        if started:
            bar.stop()
