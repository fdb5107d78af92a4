"""Leaderboards: `leaderboards/<dataset>/<split>/<entry id>.json`, one entry per submission with
its predictions kept, so that every entry can be re-scored when the metrics change; rendered
as markdown (a paper-style summary with the paper's figures as a reference row, and per-task
detail) into `leaderboard.md` beside the entries."""

from __future__ import annotations

import datetime as dt
import json
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..atomic import write_text_atomic
from ..errors import VtsError
from . import metrics as M
from .magnitude import slip_motion
from .report import cell, evaluate_submission, score
from .result import DatasetRef, EvalResult, TaskResult, tasks_from_dict, tasks_to_dict
from .submission import Submission, load_truth, open_dataset
from .tasks import BOARDS, TASKS, Column, headline_column, kind_of, task_columns

if TYPE_CHECKING:
    from ..dataset.read.loader import VtsDataset

ENTRY_VERSION = 1
#: The paper's figures (accuracy %), by split, shown as a reference row.
PAPER: dict[str, dict[str, float]] = {
    "seen": {"state": 99.68, "direction": 96.95},
    "unseen_objects": {"state": 95.5, "direction": 91.5},
    "static_sessions": {"object": 98.80},
    "static_locations": {"object": 98.80},
}
PAPER_NOTE = ("Paper: TimeSformer (RGB) on the authors' real recordings; their splits, not these "
              "files, so the row is a reference, not a comparable entry. Static: ResNet-50 RGB.")


def _slug(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-")[:40] or "entry"


def entry_schema_errors(doc: Any) -> list[str]:
    """Violations of schemas/leaderboard_entry.schema.json (which refers to metrics.schema)."""
    from referencing import Registry, Resource

    from ..dataset.format.records import SCHEMA_DIR

    sch = json.loads((SCHEMA_DIR / "leaderboard_entry.schema.json").read_text())
    ms = json.loads((SCHEMA_DIR / "metrics.schema.json").read_text())
    reg = Registry().with_resource(ms["$id"], Resource.from_contents(ms))
    from ..jsonio import strict_validator

    v = strict_validator(sch, registry=reg)
    return [f"{'.'.join(map(str, e.absolute_path)) or '(top level)'}: {e.message}"
            for e in v.iter_errors(doc)]


def add(submission: str | Path, dataset: str | Path | VtsDataset, split: str, part: str = "test",
        root: str | Path = "leaderboards", meta: str | Path | None = None,
        replace: bool = False) -> Path:
    """Score a submission and store it as a leaderboard entry; returns the entry's path."""
    for what, name in (("split", split), ("part", part)):
        if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,99}", name) or ".." in name:
            raise VtsError(f"{what} name {name!r} must be letters, digits, '_', '-' or '.' "
                           "(no path)")
    from .stream import is_stream_submission

    if is_stream_submission(submission):
        return _add_stream(submission, dataset, split, part, Path(root), replace)
    result, sub, truth = evaluate_submission(submission, dataset, split, part, meta=meta)
    assert sub is not None and truth is not None
    eid, path = _entry_path(Path(root), truth.dataset, split, str(sub.meta["method"]),
                            sub.sha256, replace)
    return _write_entry(path, _entry(
        eid, result, split, part, sub.meta["method"], sub.meta.get("recipe"), sub.seeds,
        sub.meta, {"sample_ids": truth.ids, "tasks": {
            t: {str(s): a.tolist() for s, a in by.items()} for t, by in sub.preds.items()}}))


def _entry(eid: str, result: EvalResult, split: str, part: str, method: str,
           recipe: str | None, seeds: list[int], meta: Mapping[str, Any],
           predictions: Mapping[str, Any]) -> dict[str, Any]:
    """A leaderboard entry (schemas/leaderboard_entry.schema.json) of a scored result: its
    window tasks' metrics, and a stream result's scores under `stream`."""
    entry = {
        "entry_version": ENTRY_VERSION, "id": eid,
        "added": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
        "method": method, "recipe": recipe, "seeds": seeds,
        "meta": meta, "submission_sha256": result.submission.sha256,
        "dataset": result.dataset.to_dict(), "split": split, "part": part,
        "metric_version": result.metric_version, "vtsbench_version": result.vtsbench_version,
        "metrics": tasks_to_dict(result.tasks), "rescored_from": [],
        "predictions": predictions,
    }
    if result.stream is not None:
        entry["stream"] = result.stream.to_dict()
    return entry


def _write_entry(path: Path, entry: Mapping[str, Any]) -> Path:
    """Write an entry as its JSON file (its folder made); returns the path."""
    path.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(path, json.dumps(entry, indent=1, allow_nan=False) + "\n")
    return path


def _entry_path(root: Path, dataset: str, split: str, method: str, sha256: str,
                replace: bool) -> tuple[str, Path]:
    """An entry's id and file: `<root>/<dataset>/<split>/<method>-<sha8>.json`; one that exists
    is refused unless replace."""
    eid = f"{_slug(method)}-{sha256[:8]}"
    path = root / _slug(dataset) / split / f"{eid}.json"
    if path.exists() and not replace:
        raise VtsError("this submission is already on the leaderboard (use --overwrite)", path)
    return eid, path


def _add_stream(submission: str | Path, dataset: str | Path | VtsDataset, split: str, part: str,
                root: Path, replace: bool) -> Path:
    """A stream submission's entry: its scores under `stream` (no window tasks, no stored
    predictions: re-scoring it needs the submission file again)."""
    from .report import _version
    from .stream import stream_result

    result = stream_result(submission, dataset, split, part, _version())
    sr = result.stream
    assert sr is not None
    method = result.submission.method or sr.recipe
    eid, path = _entry_path(root, result.dataset.name, split, method, result.submission.sha256,
                            replace)
    return _write_entry(path, _entry(eid, result, split, part, method, sr.recipe, [0], {},
                                     {"sample_ids": [], "tasks": {}}))


def stream_cell(value: Any, show: str) -> str:
    """A stream figure as its column shows it (tasks.STREAM_COLUMNS)."""
    if value is None:
        return "-"
    return {"ms": f"{value:.0f}", "frames": f"{value:.1f}", "pct": f"{100 * value:.1f}",
            "rate": f"{value:.2f}", "int": str(value)}[show]


def render_streams(es: list[dict[str, Any]]) -> list[str]:
    """The stream board of one dataset/split folder: fastest median detection first."""
    from .tasks import STREAM_COLUMNS

    def key(e: dict[str, Any]) -> tuple[float, float]:
        s = e["stream"]
        return (s["delay_ms_p50"] if s["delay_ms_p50"] is not None else float("inf"),
                s["false_alarms_per_min"] or 0.0)

    def col(field: str, show: str) -> Callable[[dict[str, Any]], str]:
        return lambda e: stream_cell(e["stream"].get(field), show)

    cols: list[tuple[str, Callable[[dict[str, Any]], str]]] = [
        ("method", lambda e: e["method"]), ("recipe", lambda e: e["recipe"] or "-"),
        *((h, col(f, w)) for h, f, w in STREAM_COLUMNS),
        ("metric version", lambda e: e["stream"]["metric_version"])]
    rows = sorted(es, key=key)
    return ["## Streams: how fast slip is caught", "",
            "Detection delay from slip onset to the first slip call that holds; false alarms "
            "per minute of static and press; missed: share of slip episodes never called "
            "(docs/evaluation.md, Streams).", "",
            "| " + " | ".join(c for c, _ in cols) + " |", "|---" * len(cols) + "|",
            *("| " + " | ".join(md_cell(f(r)) for _, f in cols) + " |" for r in rows)]


def entries(folder: Path) -> list[tuple[Path, dict[str, Any]]]:
    """The entries of one dataset/split folder, each checked against its schema."""
    out = []
    for p in sorted(folder.glob("*.json")):
        from ..jsonio import read_json

        doc = read_json(p, "leaderboard entry")
        errs = entry_schema_errors(doc)
        if errs:
            raise VtsError(f"invalid leaderboard entry: {errs[0]}", p)
        out.append((p, doc))
    return out


def split_folders(root: str | Path) -> list[Path]:
    """Every <dataset>/<split> folder under root that holds entries."""
    return sorted({p.parent for p in Path(root).glob("*/*/*.json")})


def rescore(root: str | Path, dataset: str | Path | VtsDataset, force: bool = False
            ) -> list[Path]:
    """Re-score the entries of a dataset (a folder, a URL or a loaded one) whose metric version
    is not the current one (all with force) from their stored predictions; returns the entries
    changed."""
    ds = open_dataset(dataset)
    info = ds.info
    changed = []
    for folder in split_folders(root):
        for path, e in entries(folder):
            if e["dataset"]["name"] != info.name or "stream" in e:
                continue  # a stream entry is re-scored from its submission file
            if e["metric_version"] == M.METRIC_VERSION and not force:
                continue
            if e["dataset"]["dataset_sha256"] != info.dataset_sha256:
                raise VtsError("entry was scored on another copy of the dataset (sha256 "
                               f"{e['dataset']['dataset_sha256'][:12]}, this one "
                               f"{info.dataset_sha256[:12]})", path)
            truth = load_truth(ds, e["split"], e["part"])
            stored = e["predictions"]
            pos = {s: i for i, s in enumerate(stored["sample_ids"])}
            order = np.array([pos[s] for s in truth.ids], dtype=np.int64)
            preds = {t: {int(s): np.asarray(a, np.int64)[order] for s, a in by.items()}
                     for t, by in stored["tasks"].items()}
            sub = Submission(path, e["meta"], e["submission_sha256"], preds)
            motion = slip_motion(ds, truth.ids) if truth.kind == "slip" else None
            result = score(truth, sub, motion)
            if e["metric_version"] != result.metric_version:
                e["rescored_from"].append(e["metric_version"])
            e.update(metric_version=result.metric_version, metrics=tasks_to_dict(result.tasks),
                     vtsbench_version=result.vtsbench_version)
            write_text_atomic(path, json.dumps(e, indent=1) + "\n")
            changed.append(path)
    return changed


@dataclass(frozen=True)
class BoardEntry:
    """What the tables show of a stored entry: method, recipe, seeds, where it was scored and
    its typed scores per task."""

    method: str
    recipe: str | None
    seeds: tuple[int, ...]
    dataset: DatasetRef
    split: str
    part: str
    metric_version: str
    tasks: dict[str, TaskResult]

    @classmethod
    def from_dict(cls, e: Mapping[str, Any]) -> BoardEntry:
        return cls(e["method"], e.get("recipe"), tuple(e["seeds"]),
                   DatasetRef.from_dict(e["dataset"]), e["split"], e["part"],
                   e["metric_version"], tasks_from_dict(e["metrics"]))

    def headline(self, task: str) -> float | None:
        """The mean over seeds of a task's headline metric (None without the task)."""
        t = self.tasks.get(task)
        return None if t is None else t.mean(TASKS[task].headline)


Cells = tuple[str, Callable[[BoardEntry], str]]


def _task_cells(col: Column) -> Cells:
    return col.header, lambda e: cell(e.tasks.get(col.task), col)


def _summary_columns(kind: str) -> list[Cells]:
    """The summary table's columns: method, recipe, seeds, the kind's board, metric version."""
    head: list[Cells] = [("method", lambda e: e.method),
                         ("recipe", lambda e: e.recipe or "-"),
                         ("seeds", lambda e: str(len(e.seeds)))]
    return [*head, *(_task_cells(c) for c in BOARDS[kind].columns),
            ("metric version", lambda e: e.metric_version)]


def md_cell(value: Any) -> str:
    """A table cell of user text: one line, markdown and HTML characters escaped, so a method
    name cannot add rows, links or markup to leaderboard.md."""
    text = " ".join(str(value).split())
    text = re.sub(r"([\\`*|])", r"\\\1", text).replace("](", "]\\(").replace("][", "]\\[")
    return text.replace("<", "&lt;").replace(">", "&gt;")[:200]


def _table(cols: list[Cells], rows: list[BoardEntry]) -> list[str]:
    out = ["| " + " | ".join(c for c, _ in cols) + " |", "|---" * len(cols) + "|"]
    return out + ["| " + " | ".join(md_cell(f(r)) for _, f in cols) + " |"
                  for r in rows]


def _version_key(version: str) -> tuple[int, ...]:
    """Sort key of a semantic version: its numbers; a pre-release sorts before its release and
    build metadata (after '+') is ignored."""
    core, _, _ = version.partition("+")
    core, dash, _pre = core.partition("-")
    nums = [int(x) if x.isdigit() else 0 for x in core.split(".")]
    return (*nums, 0 if dash else 1)


def current_version(es: list[BoardEntry]) -> str:
    """The newest dataset version among the entries: the one the leaderboard ranks."""
    return max((e.dataset.dataset_version for e in es), key=_version_key)


def _title(dataset: str, split: str, part: str) -> str:
    """leaderboard.md's title: the dataset, split and part its entries were scored on."""
    return f"# {md_cell(dataset)} / {md_cell(split)} ({md_cell(part)})"


def render_folder(folder: Path) -> str:
    """The markdown of one dataset/split folder: the entries of the newest dataset version
    ranked, those scored on an earlier version listed apart as not comparable."""
    docs = [e for _, e in entries(folder)]
    streams = [e for e in docs if "stream" in e]
    every = [BoardEntry.from_dict(e) for e in docs if "stream" not in e]
    if not every:
        if not streams:
            return ""
        e0 = streams[0]
        return "\n".join([_title(e0["dataset"]["name"], e0["split"], e0["part"]), "",
                          *render_streams(streams)]) + "\n"
    version = current_version(every)
    es = [e for e in every if e.dataset.dataset_version == version]
    old = [e for e in every if e.dataset.dataset_version != version]
    kind = kind_of(list(es[0].tasks))
    main = BOARDS[kind].rank
    es.sort(key=lambda e: -(e.headline(main) or -1.0))
    split = es[0].split
    lines = [_title(es[0].dataset.name, split, es[0].part), "",
             f"Dataset version {md_cell(version)}: {len(es)} entries, best {main} accuracy "
             "first; mean ± standard deviation over seeds where there are several."
             + (f" {len(old)} entries scored on an earlier version are listed at the end." if old
                else ""), ""]
    cols = _summary_columns(kind)
    lines += _table(cols, es)
    if split in PAPER:
        ref = PAPER[split]
        cells: dict[str, Any] = {"method": "paper (reference)", "recipe": "-", "seeds": "-"}
        cells.update({headline_column(t).header: ref.get(t.name) for t in TASKS.values()})
        lines.append("| " + " | ".join("-" if cells.get(c) is None else str(cells[c])
                                        for c, _ in cols) + " |")
        lines += ["", f"_{PAPER_NOTE}_"]
    for task in TASKS.values():
        rows = [e for e in es if task.name in e.tasks]
        if not rows:
            continue
        det: list[Cells] = [("method", lambda e: e.method),
                            *(_task_cells(c) for c in task_columns(task))]
        lines += ["", f"## {task.name}", "", *_table(det, rows)]
    if old:
        old.sort(key=lambda e: (_version_key(e.dataset.dataset_version),
                                -(e.headline(main) or -1.0)))
        cols_old: list[Cells] = [("dataset version", lambda e: e.dataset.dataset_version),
                                 *cols]
        lines += ["", "## Scored on an earlier dataset version", "",
                  f"Not comparable with the entries above: the dataset changed (version "
                  f"{md_cell(version)} is current). Kept for the record; submit again on the "
                  "current version to be ranked.", "", *_table(cols_old, old)]
    if streams:
        lines += ["", *render_streams(streams)]
    return "\n".join(lines) + "\n"


def render(root: str | Path = "leaderboards") -> dict[Path, str]:
    """Write leaderboard.md in every dataset/split folder under root; {path: markdown}."""
    out = {}
    for folder in split_folders(root):
        text = render_folder(folder)
        write_text_atomic(folder / "leaderboard.md", text)
        out[folder / "leaderboard.md"] = text
    return out


def add_and_render(submission: str | Path, dataset: str | Path | VtsDataset, split: str,
                   part: str = "test", root: str | Path = "leaderboards",
                   meta: str | Path | None = None, replace: bool = False) -> Path:
    """`vtsbench leaderboard add`: store the scored entry, then re-render every board under
    root (the new entry shows at once); returns the entry's path."""
    path = add(submission, dataset, split, part, root=root, meta=meta, replace=replace)
    render(root)
    return path


def rescore_and_render(root: str | Path, dataset: str | Path | VtsDataset, force: bool = False
                       ) -> list[Path]:
    """`vtsbench leaderboard rescore`: re-score the stale entries, then re-render; returns the
    entries changed."""
    changed = rescore(root, dataset, force=force)
    render(root)
    return changed
