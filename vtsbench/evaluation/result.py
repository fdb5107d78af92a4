"""Scores as typed, frozen records: `EvalResult` is one metrics.json (metric version, dataset,
split, submission and a `TaskResult` per task: one `RunResult` per seed and the seed summary).

`to_dict()` gives exactly the JSON document `vtsbench eval` writes (same keys in the same
order, NaN already null) and `from_dict()` reads it back, from metrics.json or from a leaderboard
entry's `metrics`; `to_dict(from_dict(d)) == d` for every document eval writes.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .stream_result import StreamResult

#: A rate in [0, 1] (an angle in degrees, a pixel count) or None where undefined.
Rate = float | None
Interval = tuple[Rate, Rate]


def _interval(v: Any) -> Interval:
    return (v[0], v[1])


@dataclass(frozen=True)
class Summary:
    """One metric over seeds: seeds counted, mean, standard deviation (None for one), min, max."""

    n: int
    mean: Rate
    std: Rate
    min: Rate
    max: Rate

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Summary:
        return cls(d["n"], d["mean"], d["std"], d["min"], d["max"])

    def to_dict(self) -> dict[str, Any]:
        return {"n": self.n, "mean": self.mean, "std": self.std, "min": self.min,
                "max": self.max}


@dataclass(frozen=True)
class GroupAccuracy:
    """Accuracy of one group of samples (an object, a true state) and its size."""

    n: int
    accuracy: Rate

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> GroupAccuracy:
        return cls(d["n"], d["accuracy"])

    def to_dict(self) -> dict[str, Any]:
        return {"n": self.n, "accuracy": self.accuracy}


def _groups(d: Mapping[str, Any]) -> dict[str, GroupAccuracy]:
    return {k: GroupAccuracy.from_dict(v) for k, v in d.items()}


@dataclass(frozen=True)
class WorstObject:
    """The object of lowest accuracy."""

    object: str
    n: int
    accuracy: Rate

    def to_dict(self) -> dict[str, Any]:
        return {"object": self.object, "n": self.n, "accuracy": self.accuracy}


@dataclass(frozen=True)
class PerClass:
    """Per class, in label order: support, recall, precision, F1."""

    support: tuple[int, ...]
    recall: tuple[Rate, ...]
    precision: tuple[Rate, ...]
    f1: tuple[Rate, ...]

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> PerClass:
        return cls(tuple(d["support"]), tuple(d["recall"]), tuple(d["precision"]),
                   tuple(d["f1"]))

    def to_dict(self) -> dict[str, Any]:
        return {"support": list(self.support), "recall": list(self.recall),
                "precision": list(self.precision), "f1": list(self.f1)}


@dataclass(frozen=True)
class MagnitudeBin:
    """Direction accuracy of one slip-distance bin [lo_mm, hi_mm) (hi None: no upper end) with
    the bin's pixels at the model's input."""

    lo_mm: float
    hi_mm: float | None
    n: int
    correct: int
    accuracy: Rate
    px_min: Rate
    px_median: Rate
    px_max: Rate

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> MagnitudeBin:
        return cls(d["lo_mm"], d["hi_mm"], d["n"], d["correct"], d["accuracy"], d["px_min"],
                   d["px_median"], d["px_max"])

    def to_dict(self) -> dict[str, Any]:
        return {"lo_mm": self.lo_mm, "hi_mm": self.hi_mm, "n": self.n, "correct": self.correct,
                "accuracy": self.accuracy, "px_min": self.px_min, "px_median": self.px_median,
                "px_max": self.px_max}


@dataclass(frozen=True)
class ByMagnitude:
    """`magnitude.by_magnitude`'s result: bin edges in mm, the bins, samples of unknown motion
    and samples outside the edges."""

    edges_mm: tuple[float | None, ...]
    bins: tuple[MagnitudeBin, ...]
    n_unknown: int
    n_outside: int

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ByMagnitude:
        return cls(tuple(d["edges_mm"]), tuple(MagnitudeBin.from_dict(b) for b in d["bins"]),
                   d["n_unknown"], d["n_outside"])

    def to_dict(self) -> dict[str, Any]:
        return {"edges_mm": list(self.edges_mm), "bins": [b.to_dict() for b in self.bins],
                "n_unknown": self.n_unknown, "n_outside": self.n_outside}


@dataclass(frozen=True)
class DirectionScores:
    """What direction adds to a run: errors by bins off, within one bin, angular error, and the
    cascade with the state (end to end, slips the state missed, state given)."""

    adjacent_error_share: Rate
    within_one_bin: Rate
    mean_abs_angular_error_deg: Rate
    error_bins: tuple[int, ...]
    end_to_end_accuracy: Rate
    slips_missed_by_state: Rate
    state_given_accuracy: Rate
    end_to_end_accuracy_ci95: Interval
    by_magnitude: ByMagnitude | None = None

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> DirectionScores:
        bm = d.get("by_magnitude")
        return cls(d["adjacent_error_share"], d["within_one_bin"],
                   d["mean_abs_angular_error_deg"], tuple(d["error_bins"]),
                   d["end_to_end_accuracy"], d["slips_missed_by_state"],
                   d["state_given_accuracy"], _interval(d["end_to_end_accuracy_ci95"]),
                   None if bm is None else ByMagnitude.from_dict(bm))

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "adjacent_error_share": self.adjacent_error_share,
            "within_one_bin": self.within_one_bin,
            "mean_abs_angular_error_deg": self.mean_abs_angular_error_deg,
            "error_bins": list(self.error_bins),
            "end_to_end_accuracy": self.end_to_end_accuracy,
            "slips_missed_by_state": self.slips_missed_by_state,
            "state_given_accuracy": self.state_given_accuracy}
        if self.by_magnitude is not None:
            out["by_magnitude"] = self.by_magnitude.to_dict()
        out["end_to_end_accuracy_ci95"] = list(self.end_to_end_accuracy_ci95)
        return out


@dataclass(frozen=True)
class RunResult:
    """One seed's scores of one task: the classification figures with their bootstrap 95 %
    intervals, confusion matrix, per class and per object; direction's and state's extras."""

    seed: int
    n: int
    accuracy: Rate
    accuracy_ci95: Interval
    balanced_accuracy: Rate
    balanced_accuracy_ci95: Interval
    macro_f1: Rate
    macro_f1_ci95: Interval
    confusion: tuple[tuple[int, ...], ...]
    per_class: PerClass
    per_object: dict[str, GroupAccuracy]
    worst_object: WorstObject | None
    labels: tuple[str, ...]
    direction: DirectionScores | None = None
    per_state: dict[str, GroupAccuracy] | None = None

    def value(self, metric: str) -> Any:
        """A figure by its metric name (a direction figure from `direction`); None if absent."""
        if metric in _DIRECTION_FIELDS:
            return None if self.direction is None else getattr(self.direction, metric)
        return getattr(self, metric, None) if metric in _RUN_FIELDS else None

    def interval(self, metric: str) -> Interval | None:
        """The 95 % interval of a metric (`<metric>_ci95`), None if it has none."""
        return self.value(f"{metric}_ci95")

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> RunResult:
        w = d["worst_object"]
        ps = d.get("per_state")
        return cls(
            d["seed"], d["n"], d["accuracy"], _interval(d["accuracy_ci95"]),
            d["balanced_accuracy"], _interval(d["balanced_accuracy_ci95"]), d["macro_f1"],
            _interval(d["macro_f1_ci95"]), tuple(tuple(r) for r in d["confusion"]),
            PerClass.from_dict(d["per_class"]), _groups(d["per_object"]),
            None if not w else WorstObject(w["object"], w["n"], w["accuracy"]),
            tuple(d["labels"]),
            DirectionScores.from_dict(d) if "error_bins" in d else None,
            None if ps is None else _groups(ps))

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "seed": self.seed, "n": self.n,
            "accuracy": self.accuracy, "accuracy_ci95": list(self.accuracy_ci95),
            "balanced_accuracy": self.balanced_accuracy,
            "balanced_accuracy_ci95": list(self.balanced_accuracy_ci95),
            "macro_f1": self.macro_f1, "macro_f1_ci95": list(self.macro_f1_ci95),
            "confusion": [list(r) for r in self.confusion],
            "per_class": self.per_class.to_dict(),
            "per_object": {k: v.to_dict() for k, v in self.per_object.items()},
            "worst_object": None if self.worst_object is None else self.worst_object.to_dict()}
        if self.direction is not None:
            out.update(self.direction.to_dict())
        if self.per_state is not None:
            out["per_state"] = {k: v.to_dict() for k, v in self.per_state.items()}
        out["labels"] = list(self.labels)
        return out


_DIRECTION_FIELDS = frozenset(DirectionScores.__dataclass_fields__)
_RUN_FIELDS = frozenset(RunResult.__dataclass_fields__) - {"direction"}


@dataclass(frozen=True)
class TaskResult:
    """One task's scores: a run per seed (ascending) and each summarised metric over seeds."""

    runs: tuple[RunResult, ...]
    summary: dict[str, Summary]

    @property
    def first(self) -> RunResult:
        """The first seed's run (the one tables and figures show)."""
        return self.runs[0]

    def mean(self, metric: str) -> Rate:
        """A summarised metric's mean over seeds; None when undefined or not summarised."""
        s = self.summary.get(metric)
        return None if s is None else s.mean

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> TaskResult:
        return cls(tuple(RunResult.from_dict(r) for r in d["runs"]),
                   {k: Summary.from_dict(v) for k, v in d["summary"].items()})

    def to_dict(self) -> dict[str, Any]:
        return {"runs": [r.to_dict() for r in self.runs],
                "summary": {k: v.to_dict() for k, v in self.summary.items()}}


def tasks_from_dict(d: Mapping[str, Any]) -> dict[str, TaskResult]:
    """The `tasks` object of metrics.json (or a leaderboard entry's `metrics`), typed."""
    return {name: TaskResult.from_dict(t) for name, t in d.items()}


def tasks_to_dict(tasks: Mapping[str, TaskResult]) -> dict[str, Any]:
    """Typed task results as the `tasks` object of metrics.json."""
    return {name: t.to_dict() for name, t in tasks.items()}


@dataclass(frozen=True)
class DatasetRef:
    """The dataset scored on: its name, version and checksum."""

    name: str
    dataset_version: str
    dataset_sha256: str

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> DatasetRef:
        return cls(d["name"], d["dataset_version"], d["dataset_sha256"])

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "dataset_version": self.dataset_version,
                "dataset_sha256": self.dataset_sha256}


@dataclass(frozen=True)
class SubmissionRef:
    """The submission scored: file name, checksum, method and recipe (its metadata), seeds."""

    file: str
    sha256: str
    method: str | None
    recipe: str | None
    seeds: tuple[int, ...]

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> SubmissionRef:
        return cls(d["file"], d["sha256"], d["method"], d.get("recipe"), tuple(d["seeds"]))

    def to_dict(self) -> dict[str, Any]:
        return {"file": self.file, "sha256": self.sha256, "method": self.method,
                "recipe": self.recipe, "seeds": list(self.seeds)}


@dataclass(frozen=True)
class EvalResult:
    """One metrics.json: the metric version the scores follow, the vtsbench version, what was
    scored (dataset, split part, submission) and the scores per task."""

    metric_version: str
    vtsbench_version: str
    dataset: DatasetRef
    split: str
    part: str
    kind: str
    n_samples: int
    submission: SubmissionRef
    tasks: dict[str, TaskResult]
    #: A stream submission's scores (kind "episode", no window tasks): evaluation/stream.py.
    stream: StreamResult | None = None

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> EvalResult:
        from .stream_result import StreamResult

        return cls(d["metric_version"], d["vtsbench_version"], DatasetRef.from_dict(d["dataset"]),
                   d["split"], d["part"], d["kind"], d["n_samples"],
                   SubmissionRef.from_dict(d["submission"]), tasks_from_dict(d["tasks"]),
                   None if d.get("stream") is None else StreamResult.from_dict(d["stream"]))

    def to_dict(self) -> dict[str, Any]:
        """The metrics.json document, keys in the order eval writes them."""
        out = {"metric_version": self.metric_version, "vtsbench_version": self.vtsbench_version,
               "dataset": self.dataset.to_dict(), "split": self.split, "part": self.part,
               "kind": self.kind, "n_samples": self.n_samples,
               "submission": self.submission.to_dict(), "tasks": tasks_to_dict(self.tasks)}
        if self.stream is not None:
            out["stream"] = self.stream.to_dict()
        return out

    def to_json(self) -> str:
        """metrics.json's text."""
        import json

        return json.dumps(self.to_dict(), indent=1) + "\n"


def read_metrics(path: str | os.PathLike) -> EvalResult:
    """An EvalResult from a metrics.json file (a malformed one is a one-line error)."""
    from ..errors import VtsError
    from ..jsonio import read_json

    doc = read_json(path, "metrics JSON")
    try:
        return EvalResult.from_dict(doc)
    except (KeyError, TypeError, IndexError) as e:
        raise VtsError(f"not a metrics.json of vtsbench eval ({type(e).__name__}: {e})",
                       path) from None
