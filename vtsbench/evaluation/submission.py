"""Submissions: the truth of a split part, reading CSV or parquet predictions and their
metadata JSON, and validation that lists every problem with counts and the first offenders.

A row: `sample_id`, `task` (state, direction, object), `pred` (class index or name), optional
`seed` (integer, default 0: one complete set of predictions per seed) and optional class
scores `score_0` .. `score_{K-1}`. Metadata (`SUBMISSION.meta.json` unless given): method,
recipe, seeds, dataset version and checksum, vtsbench version
(`schemas/submission.schema.json`).
"""

from __future__ import annotations

import hashlib
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import VtsError, one_line
from ..recipes.submission import default_meta_path
from .tasks import SLIP, STATE, TASKS, tasks_of

if TYPE_CHECKING:
    from ..dataset.read.loader import VtsDataset

MAX_SHOWN = 3
#: Characters of one offender shown (a 5 MB name is cut, with its length).
MAX_EXAMPLE = 120
#: Metadata values that are one line (names, versions, paths): no control character.
ONE_LINE_KEYS = ("method", "recipe", "dataset", "dataset_version", "vtsbench_version",
                 "authors", "url")
#: An integer of at most 18 digits: longer is no class index or seed (and int() of thousands
#: of digits raises)
_INT = re.compile(r"[+-]?\d{1,18}")


@dataclass
class Truth:
    """The labels of one split part, samples sorted by id; -1 where a label is undefined."""

    dataset: str
    dataset_version: str
    dataset_sha256: str
    split: str
    part: str
    kind: str
    ids: list[str]
    objects: list[str]
    labels: dict[str, np.ndarray]
    names: dict[str, tuple[str, ...]]

    def required(self, task: str) -> np.ndarray:
        """Positions that must have a prediction: every sample, or the true slips (direction)."""
        if TASKS[task].slips_only:
            return np.flatnonzero(self.labels[STATE.name] == SLIP)
        return np.arange(len(self.ids))


def load_truth(dataset: str | Path | VtsDataset, split: str, part: str = "test") -> Truth:
    """Labels of a split part from info.json, the split file and the index (no arrays read),
    read and checked by `vtsbench.load` as any use of the dataset is (a leaking split refused).

    `dataset`: a folder, any URL `vtsbench.load` takes, or a dataset it loaded."""
    ds = open_dataset(dataset)
    root = ds.location
    info = ds.info
    if split not in info.splits:
        raise VtsError(f"no split {split!r}; splits are {', '.join(sorted(info.splits)) or '-'}",
                       root)
    sp = ds.split_file(split)
    if part not in sp.parts:
        raise VtsError(f"split {split!r} has no part {part!r}; parts are "
                       f"{', '.join(sp.parts)}", root)
    tasks = tasks_of(sp.kind)
    cols = ["sample_id", "object", *(t.label_column for t in tasks)]
    table = ds.view(sp.kind).index.select(cols).to_pydict()
    pos = {s: i for i, s in enumerate(table["sample_id"])}
    ids = sorted(sp.parts[part])
    rows = [pos[s] for s in ids if s in pos]
    if len(rows) != len(ids):
        raise VtsError(f"split {split!r} names samples missing from the index", root)

    def col(name: str) -> np.ndarray:
        return np.array([-1 if table[name][r] is None else table[name][r] for r in rows],
                        dtype=np.int64)

    labels = {t.name: col(t.label_column) for t in tasks}
    for t in tasks:
        if t.slips_only:  # undefined unless the true state is slip
            labels[t.name][labels[STATE.name] != SLIP] = -1
    names = {t.name: t.class_names(info.objects) for t in tasks}
    return Truth(info.name, info.dataset_version, info.dataset_sha256, split, part, sp.kind, ids,
                 [table["object"][r] for r in rows], labels, names)


def open_dataset(dataset: str | Path | VtsDataset) -> VtsDataset:
    """A dataset loaded by `vtsbench.load` from a folder or URL (a loaded one as it is)."""
    from ..dataset.read.loader import VtsDataset, load

    return dataset if isinstance(dataset, VtsDataset) else load(dataset)


@dataclass
class Submission:
    """Validated predictions: task -> seed -> class index per truth position (-1: none)."""

    path: Path
    meta: dict[str, Any]
    sha256: str
    preds: dict[str, dict[int, np.ndarray]] = field(default_factory=dict)

    @property
    def seeds(self) -> list[int]:
        return sorted({s for by_seed in self.preds.values() for s in by_seed})


class Problems:
    """Problem classes with their counts and first offenders, in the order first seen."""

    def __init__(self) -> None:
        self.found: dict[str, tuple[int, list[str]]] = {}

    def add(self, kind: str, example: object) -> None:
        n, ex = self.found.get(kind, (0, []))
        shown = one_line(example, MAX_EXAMPLE)
        if len(ex) < MAX_SHOWN and shown not in ex:  # short, one line, each offender once
            ex.append(shown)
        self.found[kind] = (n + 1, ex)

    def lines(self) -> list[str]:
        return [f"{kind}: {n} (first: {', '.join(ex)})" if ex and ex != [""] else kind
                for kind, (n, ex) in self.found.items()]


def read_rows(path: Path) -> dict[str, list[Any]]:
    """Columns of a CSV or parquet submission (CSV values as text)."""
    from ..jsonio import read_csv, regular_file

    if not path.is_file():
        raise VtsError("submission not found", path)
    if path.suffix.lower() == ".parquet":
        import pyarrow.parquet as pq

        regular_file(path, "submission")
        try:
            table = pq.read_table(path)
        except Exception as e:
            raise VtsError(f"not a readable parquet file ({type(e).__name__})", path) from None
        names = [n.strip().lower() for n in table.column_names]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise VtsError(f"column name {dup[0]!r} appears more than once", path)
        return table.to_pydict()
    rows = read_csv(path, "submission CSV")
    if not rows:
        return {}
    header, body = rows[0], rows[1:]
    cols: dict[str, list[Any]] = {h: [] for h in header}
    for r in body:
        for h, v in zip(header, r + [""] * (len(header) - len(r)), strict=False):
            cols[h].append(v)
    return cols


def _missing(v: Any) -> bool:
    if v is None:
        return True
    if isinstance(v, float):
        return math.isnan(v)
    return isinstance(v, str) and v.strip().lower() in ("", "nan", "na", "null", "none")


def parse_pred(v: Any, names: tuple[str, ...]) -> tuple[int | None, str | None]:
    """(class index, None) or (None, problem class) for a pred value."""
    if _missing(v):
        return None, "NaN or empty values"
    if isinstance(v, (bool, np.bool_)):
        return None, "unknown labels"
    if isinstance(v, (int, np.integer)) or (isinstance(v, float) and v.is_integer()):
        k = int(v)
    elif isinstance(v, str) and _INT.fullmatch(v.strip()):
        k = int(v.strip())
    elif isinstance(v, str):
        low = {n.lower(): i for i, n in enumerate(names)}
        i = low.get(v.strip().lower())
        return (i, None) if i is not None else (None, "unknown labels")
    else:
        return None, "unknown labels"
    return (k, None) if 0 <= k < len(names) else (None, "out-of-range class indices")


def read_meta(path: Path) -> dict[str, Any]:
    """The metadata JSON (a missing or malformed file is a one-line error)."""
    if not path.is_file():
        raise VtsError("metadata file not found (write it beside the submission as "
                       f"{path.name} or pass --meta)", path)
    from ..jsonio import read_json
    from ..limits import MAX_META_BYTES

    return read_json(path, "metadata JSON", MAX_META_BYTES)


def schema_errors(doc: Any, at: str) -> list[str]:
    """Violations of a $defs entry of schemas/submission.schema.json."""
    from ..dataset.format.records import SCHEMA_DIR

    doc_schema = json.loads((SCHEMA_DIR / "submission.schema.json").read_text())

    sch = {"$schema": doc_schema["$schema"], "$defs": doc_schema["$defs"],
           "$ref": f"#/$defs/{at}"}
    from ..jsonio import strict_validator

    v = strict_validator(sch)
    return [f"{'.'.join(map(str, e.absolute_path)) or '(top level)'}: {e.message}"
            for e in v.iter_errors(doc)]


def validate(path: str | Path, truth: Truth, meta_path: str | Path | None = None
             ) -> tuple[Submission | None, list[str]]:
    """Read and check a submission against the truth; (submission, []) or (None, problems)."""
    path = Path(path)
    meta_path = Path(meta_path) if meta_path else default_meta_path(path)
    probs = Problems()
    try:
        meta: Any = read_meta(meta_path)
    except VtsError as e:  # not found, unreadable or not JSON: a problem like the others
        probs.add(_without_path(e, meta_path), "")
        meta = None
    for e in schema_errors(meta, "metadata") if meta is not None else ():
        probs.add(f"invalid metadata ({meta_path.name})", e)
    for key in ONE_LINE_KEYS if isinstance(meta, dict) else ():
        v = meta.get(key)
        if isinstance(v, str) and v != one_line(v, len(v)):
            probs.add(f"invalid metadata ({meta_path.name})",
                      f"{key}: a line break or control character in {v!r}")
    if isinstance(meta, dict):
        v = meta.get("dataset_version")
        if isinstance(v, str) and v != truth.dataset_version:
            probs.add("wrong dataset version", f"submission {v}, dataset {truth.dataset_version}")
        s = meta.get("dataset_sha256")
        if isinstance(s, str) and s != truth.dataset_sha256:
            probs.add("wrong dataset checksum",
                      f"submission {s[:12]}, dataset {truth.dataset_sha256[:12]}")
    try:
        cols = read_rows(path)
    except VtsError as e:
        if e.path is not None and Path(e.path) == path and not path.is_file():
            raise  # no submission at all: nothing else to list
        probs.add(_without_path(e, path), "")
        return None, probs.lines()
    n = len(next(iter(cols.values()))) if cols else 0
    need = [c for c in ("sample_id", "task", "pred") if c not in cols]
    if n == 0:
        probs.add("empty file (no prediction rows)", "")
    elif need:
        probs.add("missing columns", ", ".join(need))
    preds: dict[str, dict[int, np.ndarray]] = {}
    if n and not need:
        _check_rows(cols, n, truth, probs, preds)
    if probs.found:
        return None, probs.lines()
    sha = hashlib.sha256(path.read_bytes()).hexdigest()
    return Submission(path, meta, sha, preds), []


def _without_path(err: VtsError, path: Path) -> str:
    """A VtsError's message without its leading path, naming the file by its name instead."""
    text = err.reason if err.path is not None else str(err)
    return f"{text} ({path.name})" if path.name not in text else text


def _check_rows(cols: dict[str, list[Any]], n: int, truth: Truth, probs: Problems,
                preds: dict[str, dict[int, np.ndarray]]) -> None:
    pos = {s: i for i, s in enumerate(truth.ids)}
    scores = [c for c in cols if c.startswith("score_")]
    seeds = cols.get("seed")
    seen: set[tuple[str, str, int]] = set()
    for r in range(n):
        sid, task = cols["sample_id"][r], cols["task"][r]
        sid = "" if _missing(sid) else str(sid).strip()
        task = "" if _missing(task) else str(task).strip()
        if not sid:
            probs.add("NaN or empty values", f"row {r + 1} sample_id")
            continue
        if task not in TASKS or TASKS[task].kind != truth.kind:
            probs.add(f"unknown tasks (a {truth.kind} split scores "
                      f"{', '.join(t.name for t in tasks_of(truth.kind))})", task or "''")
            continue
        seed = 0
        if seeds is not None:
            sv = seeds[r]
            if isinstance(sv, float) and sv.is_integer():
                sv = int(sv)
            if _missing(sv) or not _INT.fullmatch(str(sv).strip()) or int(str(sv)) < 0:
                probs.add("invalid seeds (need an integer >= 0)", f"row {r + 1}: {sv}")
                continue
            seed = int(str(sv))
        for c in scores:
            v = cols[c][r]
            if v is None or (isinstance(v, str) and v.strip() == ""):
                continue  # no score for this class (another task's classes)
            try:
                bad = not math.isfinite(float(v))
            except (TypeError, ValueError):
                bad = True
            if bad:
                probs.add("NaN or empty values", f"{sid} {task} {c}")
        k, why = parse_pred(cols["pred"][r], truth.names[task])
        if why:
            probs.add(why, f"{sid} {task} {cols['pred'][r]!r}")
            continue
        if sid not in pos:
            probs.add(f"ids not in split {truth.split}/{truth.part}", sid)
            continue
        key = (sid, task, seed)
        if key in seen:
            probs.add("duplicate rows (same sample_id, task and seed)", f"{sid} {task}")
            continue
        seen.add(key)
        arr = preds.setdefault(task, {}).setdefault(seed, np.full(len(truth.ids), -1, np.int64))
        arr[pos[sid]] = k
    if not preds and truth.ids:  # no row names a sample of the part: every one is missing
        probs.found[f"missing ids (0 of {len(truth.ids)} {truth.part} samples predicted)"] = (
            len(truth.ids), [one_line(s, MAX_EXAMPLE) for s in truth.ids[:MAX_SHOWN]])
    for task, by_seed in preds.items():
        req = truth.required(task)
        for seed, arr in sorted(by_seed.items()):
            for i in req[arr[req] < 0]:
                probs.add("missing ids", f"{truth.ids[i]} ({task}, seed {seed})")


def load_submission(path: str | Path, truth: Truth, meta_path: str | Path | None = None
                    ) -> Submission:
    """validate(), raising one VtsError line that lists every problem class."""
    sub, problems = validate(path, truth, meta_path)
    if sub is None:
        raise VtsError(f"{len(problems)} problem(s): " + "; ".join(problems), path)
    return sub
