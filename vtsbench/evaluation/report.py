"""Scoring a validated submission: metrics.json (with the metric version), report.md and
confusion-matrix PNGs (counts and row-normalised; directions drawn as compass arrows)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..atomic import write_text_atomic
from . import metrics as M
from .magnitude import by_magnitude, distances, per_state, slip_motion
from .result import (
    ByMagnitude,
    DatasetRef,
    EvalResult,
    RunResult,
    SubmissionRef,
    Summary,
    TaskResult,
)
from .submission import Submission, Truth, load_submission, load_truth, open_dataset
from .tasks import DIRECTION, SLIP, STATE, TASKS, Column, task_columns

if TYPE_CHECKING:
    from ..dataset.read.loader import VtsDataset


def score_run(truth: Truth, preds: dict[str, np.ndarray], seed: int = 0,
              dist: tuple[np.ndarray, np.ndarray] | None = None) -> dict[str, RunResult]:
    """Metrics of one seed's predictions (task -> class per truth position, -1 = none).

    `dist`: slip distance per truth position in mm and in pixels at the model's input
    (`magnitude.distances`); given, direction is also scored per distance bin."""
    out: dict[str, RunResult] = {}
    objects = np.asarray(truth.objects)
    for task, pred in preds.items():
        req = truth.required(task)
        true = truth.labels[task][req]
        rep = M.classification_report(true, pred[req], len(truth.names[task]),
                                      groups=objects[req].tolist(), seed=seed)
        if task == DIRECTION.name:
            rep.update(M.direction_metrics(true, pred[req]))
            st = truth.labels[STATE.name]
            sp = preds.get(STATE.name)
            c = M.cascade(st, sp if sp is not None else np.full_like(st, -1),
                          truth.labels[DIRECTION.name], pred, slip=SLIP)
            rep["end_to_end_accuracy"] = c["end_to_end_accuracy"] if sp is not None else M.NAN
            rep["slips_missed_by_state"] = c["slips_missed_by_state"] if sp is not None \
                else M.NAN
            rep["state_given_accuracy"] = c["state_given_accuracy"]
            if dist is not None:
                rep["by_magnitude"] = by_magnitude(pred[req] == true, dist[0][req], dist[1][req])
            if sp is not None and len(req) > 1:
                ok = ((pred[req] == true) & (sp[req] == SLIP)).astype(float)
                idx = M.bootstrap_indices(len(req), seed=seed)
                rep["end_to_end_accuracy_ci95"] = M.interval(ok[idx].mean(1))
            else:
                rep["end_to_end_accuracy_ci95"] = [rep["end_to_end_accuracy"]] * 2
        if task == STATE.name:
            rep["per_state"] = per_state(true, pred[req], truth.names[task])
        rep["labels"] = list(truth.names[task])
        out[task] = RunResult.from_dict(M.jsonable({"seed": seed, **rep}))
    return out


def score(truth: Truth, sub: Submission,
          motion: dict[str, np.ndarray] | None = None) -> EvalResult:
    """The scores of a submission: per task (TASKS order), one run per seed and a summary over
    seeds of the task's summary metrics.

    `motion` (`magnitude.slip_motion` of the truth's ids) adds direction accuracy per slip
    distance, in pixels at the input scale the submission's metadata states."""
    dist = None if motion is None else distances(motion, sub.meta.get("input_scale_xy"))
    by_seed: dict[int, dict[str, RunResult]] = {}
    tasks: dict[str, TaskResult] = {}
    for task in [t for t in TASKS.values() if t.name in sub.preds]:
        runs = []
        for seed in sorted(sub.preds[task.name]):
            if seed not in by_seed:  # every task of one seed is scored together
                by_seed[seed] = score_run(truth, {t: sub.preds[t][seed] for t in sub.preds
                                                  if seed in sub.preds[t]}, seed, dist)
            runs.append(by_seed[seed][task.name])
        tasks[task.name] = TaskResult(tuple(runs), {
            m: Summary.from_dict(M.jsonable(M.seed_summary([r.value(m) for r in runs])))
            for m in task.summary})
    return EvalResult(
        M.METRIC_VERSION, _version(),
        DatasetRef(truth.dataset, truth.dataset_version, truth.dataset_sha256),
        truth.split, truth.part, truth.kind, len(truth.ids),
        SubmissionRef(sub.path.name, sub.sha256, sub.meta.get("method"), sub.meta.get("recipe"),
                      tuple(sub.seeds)),
        tasks)


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("vtsbench")
    except PackageNotFoundError:  # pragma: no cover - running from a source tree
        return "0+unknown"


def pct(v: Any) -> str:
    return "-" if v is None else f"{100 * v:.2f}"


def cell(t: TaskResult | None, col: Column) -> str:
    """One table cell: a task's figure shown as its column says ('-' without the task)."""
    if t is None:
        return "-"
    if col.show == "mean_std":
        s = t.summary[col.metric]
        return pct(s.mean) + (f" ± {100 * s.std:.2f}" if s.std is not None else "")
    if col.show == "pct":
        return pct(t.mean(col.metric))
    if col.show == "deg":
        v = t.mean(col.metric)
        return "-" if v is None else f"{v:.1f}"
    if col.show == "worst":
        w = t.first.worst_object
        return "-" if w is None else f"{w.object} {pct(w.accuracy)}"
    if col.show == "n":
        return str(t.first.n)
    ci = t.first.interval(col.metric)
    return "-" if ci is None else f"[{pct(ci[0])}, {pct(ci[1])}]"


SUMMARY_HEAD = ("task", "n", "accuracy %", "95 % CI (seed 1st)", "balanced %", "macro-F1 %",
                "worst object %")


def summary_rows(result: EvalResult | Mapping[str, Any]) -> list[tuple[str, ...]]:
    """(task, n, accuracy %, 95 % interval, balanced %, macro-F1 %, worst object) per task
    (SUMMARY_HEAD); a metrics.json dict is read as its EvalResult."""
    if not isinstance(result, EvalResult):
        result = EvalResult.from_dict(result)
    return [(name, *(cell(t, c) for c in task_columns(TASKS[name], detail=False)))
            for name, t in result.tasks.items()]


def summary_title(result: EvalResult) -> str:
    """The title of the printed summary: method, split part and metric version."""
    return (f"{result.submission.method} on {result.split}/{result.part} "
            f"(metric version {result.metric_version})")


def direction_line(result: EvalResult) -> str | None:
    """One printed line of direction's cascade figures (None without direction)."""
    d = result.tasks.get(DIRECTION.name)
    if d is None:
        return None
    e2e, mae = d.mean("end_to_end_accuracy"), d.mean("mean_abs_angular_error_deg")
    return (f"direction: end to end {'-' if e2e is None else f'{100 * e2e:.2f} %'}, "
            f"within one bin {100 * (d.mean('within_one_bin') or 0):.2f} %, "
            f"angular error {'-' if mae is None else f'{mae:.1f}'} deg")


def _heading(result: EvalResult) -> list[str]:
    """report.md's title and what was scored: dataset, split part, submission; a window
    submission's seeds and versions too (a stream's section states its own), then a blank."""
    sub, ds = result.submission, result.dataset
    stream = result.stream is not None
    lines = [f"# Evaluation: {sub.method or sub.file}", "",
             f"- dataset: {ds.name} {ds.dataset_version} (sha256 {ds.dataset_sha256[:12]})",
             f"- split: {result.split} / {result.part} ({result.n_samples} "
             + ("episodes)" if stream else f"{result.kind} samples)"),
             f"- submission: {sub.file} (sha256 {sub.sha256[:12]})"
             + ("" if stream else f", seeds {', '.join(map(str, sub.seeds))}")]
    if not stream:
        lines.append(f"- metric version {result.metric_version}, vtsbench "
                     f"{result.vtsbench_version}")
    return [*lines, ""]


def render_markdown(result: EvalResult, figures: list[str]) -> str:
    """report.md: the summary, direction metrics, per-object accuracy, confusion matrices
    (a stream submission: its stream section and timeline)."""
    if result.stream is not None:
        from .stream_result import stream_markdown

        lines = [*_heading(result), *stream_markdown(result.stream)]
        if figures:
            lines += ["", "## Figures", ""] + [f"![{p}]({p})" for p in figures]
        return "\n".join(lines) + "\n"
    lines = [*_heading(result),
             "| " + " | ".join(SUMMARY_HEAD) + " |", "|---" * len(SUMMARY_HEAD) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in summary_rows(result)]
    d = result.tasks.get(DIRECTION.name)
    if d is not None:
        r0 = d.first
        assert r0.direction is not None  # a direction run carries its direction figures

        def f(m: str) -> str:
            return pct(d.mean(m))

        mae = d.mean("mean_abs_angular_error_deg")
        lines += ["", "## Direction (on the truly slipping sequences)", "",
                  f"- state given: {f('accuracy')} %; end to end (a wrong state is a miss): "
                  f"{f('end_to_end_accuracy')} %",
                  f"- within one bin: {f('within_one_bin')} %; mean absolute angular error: "
                  f"{'-' if mae is None else f'{mae:.1f}'} degrees",
                  f"- share of errors on the adjacent bin: {f('adjacent_error_share')} %",
                  f"- errors by bins off (0..4, seed {r0.seed}): {list(r0.direction.error_bins)}"]
        if r0.direction.by_magnitude is not None:
            lines += ["", f"Direction by slip distance (state given, seed {r0.seed}):", ""]
            lines += magnitude_table(r0.direction.by_magnitude)
    st = result.tasks.get(STATE.name)
    if st is not None and st.first.per_state:
        lines += ["", f"State accuracy per true state (seed {st.first.seed}): " + "; ".join(
            f"{k} {pct(v.accuracy)} % (n {v.n})" for k, v in st.first.per_state.items())]
    for task, t in result.tasks.items():
        r0 = t.first
        lines += ["", f"## {task}: per object (seed {r0.seed})", "",
                  "| object | n | accuracy % |", "|---|---:|---:|"]
        lines += [f"| {o} | {v.n} | {pct(v.accuracy)} |" for o, v in r0.per_object.items()]
        labels = [_label(task, i, n) for i, n in enumerate(r0.labels)]
        lines += ["", f"Confusion (rows true, columns predicted; seed {r0.seed}):", "",
                  "| true \\ pred | " + " | ".join(labels) + " |", "|---" * (len(labels) + 1) + "|"]
        lines += [f"| {labels[i]} | " + " | ".join(map(str, row)) + " |"
                  for i, row in enumerate(r0.confusion)]
    if figures:
        lines += ["", "## Figures", ""] + [f"![{p}]({p})" for p in figures]
    return "\n".join(lines) + "\n"


def magnitude_table(bm: ByMagnitude) -> list[str]:
    """Markdown rows of a `by_magnitude` result: bin in mm, pixels at the input, n, accuracy."""
    def px(v: float | None) -> str:
        return "-" if v is None else f"{v:.1f}"

    rows = ["| slip mm | px at the model's input (min / median / max) | n | direction % |",
            "|---|---|---:|---:|"]
    for b in bm.bins:
        hi = "inf" if b.hi_mm is None else f"{b.hi_mm:g}"
        rows.append(f"| [{b.lo_mm:g}, {hi}) | {px(b.px_min)} / {px(b.px_median)} / "
                    f"{px(b.px_max)} | {b.n} | {pct(b.accuracy)} |")
    return rows


def _label(task: str, i: int, name: str) -> str:
    shown = TASKS[task].axis_labels
    return name if shown is None else shown[i]


def figure_title(result: EvalResult, task: str, n: int) -> str:
    """A figure's title: what was scored (method, split, part) and on how many samples."""
    method = result.submission.method or result.submission.file or "submission"
    return f"{method}: {task} on {result.split}/{result.part}, n = {n}"


def write_figures(result: EvalResult, out: Path) -> list[str]:
    """confusion_<task>.png per task: counts (left) and row-normalised (right), first seed,
    titled with the method, split, part and n; at print quality (vtsbench.figures).

    Direction classes are labelled as compass arrows (→ E, ↗ NE, ↑ N, ...). Uses matplotlib's
    object API (no pyplot) to keep the start-up short.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from ..figures import MIN_FONT_PT as FONT
    from ..figures import print_style, save_png

    names = []
    for task, t in result.tasks.items():
        r0 = t.first
        cm = np.asarray(r0.confusion, dtype=float)
        labels = [_label(task, i, n) for i, n in enumerate(r0.labels)]
        with np.errstate(invalid="ignore", divide="ignore"):
            norm = cm / cm.sum(1, keepdims=True)
        k = len(labels)
        side = 2.0 + 0.5 * k
        upright = TASKS[task].axis_labels is not None  # short labels: not turned
        with print_style():
            fig = Figure(figsize=(2 * side + 0.6, side + 0.8))
            FigureCanvasAgg(fig)
            fig.subplots_adjust(left=0.14, right=0.98, bottom=0.2, top=0.84, wspace=0.45)
            fig.suptitle(figure_title(result, task, int(cm.sum())), fontsize=FONT + 2)
            for col, (kind, mat) in enumerate((("counts", cm), ("row-normalised", norm))):
                ax = fig.add_subplot(1, 2, col + 1)
                show = np.nan_to_num(mat)
                top = max(float(show.max()), 1e-9)
                ax.imshow(show, cmap="Blues", vmin=0, vmax=top if col == 0 else 1.0)
                ax.set_xticks(range(k), labels, rotation=0 if upright else 90, fontsize=FONT)
                ax.set_yticks(range(k), labels, fontsize=FONT)
                ax.set_xlabel("predicted", fontsize=FONT + 1)
                ax.set_ylabel("true", fontsize=FONT + 1)
                ax.set_title(kind, fontsize=FONT + 1)
                if k <= 15:
                    for i, j in zip(*np.nonzero(show), strict=True):
                        v = mat[i, j]
                        ax.text(j, i, f"{int(v)}" if col == 0 else f"{v:.2f}", ha="center",
                                va="center", fontsize=FONT,
                                color="white" if show[i, j] > 0.6 * (top if col == 0 else 1)
                                else "black")
            name = f"confusion_{task}.png"
            save_png(fig, out / name)
        names.append(name)
    return names


def evaluate_submission(submission: str | Path, dataset: str | Path | VtsDataset, split: str,
                        part: str = "test", out: str | Path | None = None,
                        meta: str | Path | None = None, figures: bool = True
                        ) -> tuple[EvalResult, Submission | None, Truth | None]:
    """Validate and score a submission on a dataset (a folder, any URL `vtsbench.load` takes,
    or a loaded dataset) and, when out is given, write metrics.json, report.md and PNGs.
    A stream submission (JSON lines starting with a stream header) is scored by
    evaluation/stream.py: the result's `stream`, with no Submission or Truth."""
    from .stream import (
        is_stream_submission,
        read_stream_submission,
        stream_result,
        write_stream_figure,
    )

    if is_stream_submission(submission):
        ds = open_dataset(dataset)
        streams = read_stream_submission(submission)  # read and checked once: scores, figure
        res = stream_result(streams, ds, split, part, _version())
        if out is not None:
            out = Path(out)
            out.mkdir(parents=True, exist_ok=True)
            names = [write_stream_figure(res, ds, streams, out)] if figures else []
            write_text_atomic(out / "metrics.json", res.to_json())
            write_text_atomic(out / "report.md", render_markdown(res, names))
        return res, None, None
    ds = open_dataset(dataset)
    truth = load_truth(ds, split, part)
    sub = load_submission(submission, truth, meta)
    result = score(truth, sub, slip_motion(ds, truth.ids) if truth.kind == "slip" else None)
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        names = write_figures(result, out) if figures else []
        write_text_atomic(out / "metrics.json", result.to_json())
        write_text_atomic(out / "report.md", render_markdown(result, names))
    return result, sub, truth


def evaluate(submission: str | Path, dataset: str | Path, split: str, part: str = "test",
             out: str | Path | None = None, meta: str | Path | None = None,
             figures: bool = True) -> tuple[dict[str, Any], Submission | None, Truth | None]:
    """`evaluate_submission` with the result as its metrics.json document (a dict)."""
    result, sub, truth = evaluate_submission(submission, dataset, split, part, out, meta,
                                             figures)
    return result.to_dict(), sub, truth
