"""Progress as plain lines for output that is not a terminal (logs, CI, `| tee`), where a live
bar prints nothing until the end: one line per task at most every few seconds, and the last."""

from __future__ import annotations

import sys
import time
from typing import Any, TextIO

#: Seconds between two lines of the same task.
EVERY_S = 5.0


def is_terminal(stream: TextIO | None = None) -> bool:
    """Whether the stream (stderr by default) is an interactive terminal."""
    s = stream if stream is not None else sys.stderr
    try:
        return bool(s.isatty())
    except (AttributeError, ValueError):
        return False


class LineProgress:
    """The add_task/advance interface of rich's Progress, printed as lines such as
    `frames: 1200/4800 (25 %), 95/s, about 38 s left`."""

    def __init__(self, stream: TextIO | None = None, every_s: float = EVERY_S) -> None:
        self.stream = stream
        self.every_s = every_s
        self.tasks: list[dict[str, Any]] = []

    def __enter__(self) -> LineProgress:
        return self

    def __exit__(self, *exc: object) -> None:
        for k, t in enumerate(self.tasks):
            if t["printed"] != t["done"]:
                self._line(k)

    def add_task(self, description: str, total: float | None = None, completed: float = 0,
                 **_: Any) -> int:
        now = time.monotonic()
        self.tasks.append({"desc": description, "total": total, "done": completed,
                           "start_done": completed, "t0": now, "last": now, "printed": None})
        return len(self.tasks) - 1

    def start(self) -> None:
        """Nothing to start (rich's Progress starts its live display here)."""

    def stop(self) -> None:
        """The last line of every task not yet printed at its end."""
        self.__exit__()

    def update(self, task: int, completed: float | None = None,
               description: str | None = None, **_: Any) -> None:
        """Set a task's count and description (rich's update); prints as advance does."""
        t = self.tasks[task]
        if description is not None:
            t["desc"] = description
        if completed is not None:
            self.advance(task, completed - t["done"])

    def advance(self, task: int, advance: float = 1) -> None:
        t = self.tasks[task]
        t["done"] += advance
        now = time.monotonic()
        if now - t["last"] >= self.every_s or (t["total"] and t["done"] >= t["total"]):
            self._line(task)

    def _line(self, task: int) -> None:
        t = self.tasks[task]
        now = time.monotonic()
        t["last"], t["printed"] = now, t["done"]
        done, total = t["done"], t["total"]
        rate = (done - t["start_done"]) / max(now - t["t0"], 1e-9)
        text = f"{t['desc']}: {done:g}"
        if total:
            text += f"/{total:g} ({100 * done / total:.0f} %)"
        if rate > 0:
            text += f", {rate:.3g}/s"
            if total and done < total:
                text += f", about {(total - done) / rate:.0f} s left"
        print(text, file=self.stream if self.stream is not None else sys.stderr, flush=True)


def progress_bar(*columns: Any, transient: bool = True, **kwargs: Any) -> Any:
    """The progress display of a long command, on stderr: rich's live bar (with these columns)
    on a terminal, `LineProgress` lines anywhere else. Both have add_task, advance, update,
    start, stop and work as context managers."""
    if not is_terminal():
        return LineProgress()
    from rich.console import Console
    from rich.progress import Progress

    return Progress(*columns, console=Console(stderr=True), transient=transient, **kwargs)
