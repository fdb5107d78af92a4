"""The evaluation tasks, each declared once: the index kind it is scored on, where its labels
come from and their classes, the metrics summarised over seeds, its headline metric, and the
leaderboard columns that show it. Submission checks, scoring, reports, leaderboards and the
results page read these declarations instead of naming tasks and metrics themselves."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from ..labels import DIRECTION_NAMES, STATES

#: Class index of the slip state: direction is defined (and scored) on true slips only.
SLIP = STATES.index("slip")

#: How a column shows a task's figures: `mean_std` (mean over seeds, ± their standard deviation
#: when there are several, %), `pct` (mean over seeds, %), `deg` (mean, degrees, 1 decimal),
#: `worst` (the first seed's worst object and its accuracy %), `n` (the first seed's sample
#: count), `ci` (the first seed's 95 % interval of the metric, %).
SHOWS = ("mean_std", "pct", "deg", "worst", "n", "ci")


@dataclass(frozen=True)
class Column:
    """A table column of one task's figure: its header, the task, the metric and how it shows."""

    header: str
    task: str
    metric: str
    show: str = "pct"

    def __post_init__(self) -> None:
        if self.show not in SHOWS:
            raise ValueError(f"column {self.header!r}: unknown show {self.show!r}")


@dataclass(frozen=True)
class Task:
    """One task: the index kind it is scored on, the index column of its class indices, its
    class names (None: the dataset's objects, from info.json), whether it is defined only on the
    truly slipping samples, the metrics summarised over seeds (mean and spread), the metric it
    is known by (ranked on, shown first) and extra columns of its own leaderboard table."""

    name: str
    kind: str
    label_column: str
    classes: tuple[str, ...] | None
    slips_only: bool
    summary: tuple[str, ...]
    headline: str = "accuracy"
    detail: tuple[Column, ...] = ()
    #: Class labels of figures and confusion tables, when not the class names.
    axis_labels: tuple[str, ...] | None = None

    def class_names(self, objects: Sequence[str]) -> tuple[str, ...]:
        """The class names in label order (the dataset's objects for a task without its own)."""
        return self.classes if self.classes is not None else tuple(objects)


CLASSIFICATION = ("accuracy", "balanced_accuracy", "macro_f1")

STATE = Task("state", "slip", "state_idx", STATES, False, CLASSIFICATION)
DIRECTION = Task(
    "direction", "slip", "direction", DIRECTION_NAMES, True,
    (*CLASSIFICATION, "within_one_bin", "mean_abs_angular_error_deg", "adjacent_error_share",
     "end_to_end_accuracy"),
    detail=(Column("adjacent share of errors %", "direction", "adjacent_error_share"),),
    axis_labels=("→ E", "↗ NE", "↑ N", "↖ NW", "← W", "↙ SW", "↓ S", "↘ SE"))
OBJECT = Task("object", "static", "class_idx", None, False, CLASSIFICATION)

#: Every task by name, in the order results list them.
TASKS: dict[str, Task] = {t.name: t for t in (STATE, DIRECTION, OBJECT)}

#: The stream task: a monitor's calls on continuous episodes, scored against their per-frame
#: labels (evaluation/stream.py: delay from slip onset, false alarms, missed slips, direction
#: at detection). Its submissions are JSON lines, not CSV columns, so it is not in TASKS.
STREAM = Task("stream", "episode", "state", STATES, False, (), headline="delay_ms_p50")
#: Its leaderboard columns: header, the StreamResult field, how it shows (`ms` whole ms,
#: `frames` 1 decimal, `pct` %, `rate` 2 decimals, `int`).
STREAM_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("debounce", "smoothing", "int"),
    ("episodes", "n_episodes", "int"),
    ("delay p50 (ms)", "delay_ms_p50", "ms"),
    ("delay p90 (ms)", "delay_ms_p90", "ms"),
    ("delay p50 (frames)", "delay_frames_p50", "frames"),
    ("missed %", "missed", "pct"),
    ("false alarms / min", "false_alarms_per_min", "rate"),
    ("direction at detection %", "direction_accuracy", "pct"),
    ("within one bin %", "direction_within_one_bin", "pct"),
    ("fps sustained", "fps_sustained", "frames"),
    ("latency p95 (ms)", "latency_ms_p95", "frames"))


@dataclass(frozen=True)
class Board:
    """A leaderboard's summary table for one index kind: the task whose headline ranks the
    entries and the columns after method, recipe and seeds (one kind's tasks interleave)."""

    kind: str
    rank: str
    columns: tuple[Column, ...]


BOARDS: dict[str, Board] = {
    "slip": Board("slip", "state", (
        Column("state %", "state", "accuracy", "mean_std"),
        Column("direction % (state given)", "direction", "accuracy", "mean_std"),
        Column("direction % end to end", "direction", "end_to_end_accuracy"),
        Column("within one bin %", "direction", "within_one_bin"),
        Column("angular error (deg)", "direction", "mean_abs_angular_error_deg", "deg"),
        Column("worst object, state %", "state", "worst_object", "worst"))),
    "static": Board("static", "object", (
        Column("object %", "object", "accuracy", "mean_std"),
        Column("balanced %", "object", "balanced_accuracy"),
        Column("macro-F1 %", "object", "macro_f1"),
        Column("worst object %", "object", "worst_object", "worst"))),
}


def tasks_of(kind: str) -> tuple[Task, ...]:
    """The tasks scored on samples of one index kind ("slip" or "static"), in TASKS order."""
    return tuple(t for t in TASKS.values() if t.kind == kind)


def kind_of(tasks: Sequence[str], default: str = "static") -> str:
    """The index kind of a set of scored tasks (default when there is none)."""
    return next((TASKS[t].kind for t in tasks if t in TASKS), default)


def board_columns(task: Task) -> tuple[Column, ...]:
    """The leaderboard summary columns that show a task."""
    return tuple(c for c in BOARDS[task.kind].columns if c.task == task.name)


def headline_column(task: Task) -> Column:
    """The leaderboard column of a task's headline metric (where the paper's figure goes)."""
    return next(c for c in board_columns(task)
                if c.metric == task.headline and c.show == "mean_std")


def task_columns(task: Task, ci_header: str = "95 % CI (first seed)",
                 detail: bool = True) -> tuple[Column, ...]:
    """The columns of a task's own table (report summary, leaderboard detail): test n, headline
    mean ± std, its interval, balanced accuracy, macro-F1, the task's extra columns (with
    detail), worst object."""
    t = task.name
    return (Column("n", t, task.headline, "n"),
            Column("accuracy %", t, task.headline, "mean_std"),
            Column(ci_header, t, task.headline, "ci"),
            Column("balanced %", t, "balanced_accuracy"),
            Column("macro-F1 %", t, "macro_f1"),
            *(task.detail if detail else ()),
            Column("worst object %", t, "worst_object", "worst"))
