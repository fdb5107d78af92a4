"""Scoring a validated submission: metrics.json (with the metric version), report.md and
confusion-matrix PNGs (counts and row-normalised; directions drawn as compass arrows)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from ..atomic import write_text_atomic
from . import metrics as M
from .magnitude import by_magnitude, distances, per_state, slip_motion
from .submission import SLIP, Submission, Truth, load_submission, load_truth

#: Metrics summarised over seeds (mean and spread) per task.
HEADLINE = {
    "state": ("accuracy", "balanced_accuracy", "macro_f1"),
    "direction": ("accuracy", "balanced_accuracy", "macro_f1", "within_one_bin",
                  "mean_abs_angular_error_deg", "adjacent_error_share", "end_to_end_accuracy"),
    "object": ("accuracy", "balanced_accuracy", "macro_f1"),
}
ARROWS = ("→", "↗", "↑", "↖", "←", "↙", "↓", "↘")
COMPASS = ("E", "NE", "N", "NW", "W", "SW", "S", "SE")


def score_run(truth: Truth, preds: dict[str, np.ndarray], seed: int = 0,
              dist: tuple[np.ndarray, np.ndarray] | None = None) -> dict[str, Any]:
    """Metrics of one seed's predictions (task -> class per truth position, -1 = none).

    `dist`: slip distance per truth position in mm and in pixels at the model's input
    (`magnitude.distances`); given, direction is also scored per distance bin."""
    out: dict[str, Any] = {}
    objects = np.asarray(truth.objects)
    for task, pred in preds.items():
        req = truth.required(task)
        true = truth.labels[task][req]
        rep = M.classification_report(true, pred[req], len(truth.names[task]),
                                      groups=objects[req].tolist(), seed=seed)
        if task == "direction":
            rep.update(M.direction_metrics(true, pred[req]))
            st = truth.labels["state"]
            sp = preds.get("state")
            c = M.cascade(st, sp if sp is not None else np.full_like(st, -1),
                          truth.labels["direction"], pred)
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
        if task == "state":
            rep["per_state"] = per_state(true, pred[req], truth.names[task])
        rep["labels"] = list(truth.names[task])
        out[task] = rep
    return out


def score(truth: Truth, sub: Submission,
          motion: dict[str, np.ndarray] | None = None) -> dict[str, Any]:
    """The metrics document of a submission: per task, one run per seed and a seed summary.

    `motion` (`magnitude.slip_motion` of the truth's ids) adds direction accuracy per slip
    distance, in pixels at the input scale the submission's metadata states."""
    tasks: dict[str, Any] = {}
    dist = None if motion is None else distances(motion, sub.meta.get("input_scale_xy"))
    for task in [t for t in HEADLINE if t in sub.preds]:
        runs = []
        for seed in sorted(sub.preds[task]):
            run = score_run(truth, {t: sub.preds[t][seed] for t in sub.preds
                                    if seed in sub.preds[t]}, seed, dist)[task]
            runs.append({"seed": seed, **run})
        tasks[task] = {"runs": runs, "summary": {
            m: M.seed_summary([r.get(m) for r in runs]) for m in HEADLINE[task]}}
    return M.jsonable({
        "metric_version": M.METRIC_VERSION,
        "vtsbench_version": _version(),
        "dataset": {"name": truth.dataset, "dataset_version": truth.dataset_version,
                    "dataset_sha256": truth.dataset_sha256},
        "split": truth.split, "part": truth.part, "kind": truth.kind,
        "n_samples": len(truth.ids),
        "submission": {"file": sub.path.name, "sha256": sub.sha256,
                       "method": sub.meta.get("method"), "recipe": sub.meta.get("recipe"),
                       "seeds": sub.seeds},
        "tasks": tasks,
    })


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("vtsbench")
    except PackageNotFoundError:  # pragma: no cover - running from a source tree
        return "0+unknown"


def pct(v: Any) -> str:
    return "-" if v is None else f"{100 * v:.2f}"


def summary_rows(doc: dict[str, Any]) -> list[tuple[str, ...]]:
    """(task, n, accuracy %, 95 % interval, balanced %, macro-F1 %, worst object) per task."""
    rows = []
    for task, t in doc["tasks"].items():
        r0 = t["runs"][0]
        acc = t["summary"]["accuracy"]
        spread = f" ± {100 * acc['std']:.2f}" if acc["std"] is not None else ""
        ci = r0["accuracy_ci95"]
        w = r0.get("worst_object")
        rows.append((task, str(r0["n"]), pct(acc["mean"]) + spread,
                     f"[{pct(ci[0])}, {pct(ci[1])}]",
                     pct(t["summary"]["balanced_accuracy"]["mean"]),
                     pct(t["summary"]["macro_f1"]["mean"]),
                     "-" if not w else f"{w['object']} {pct(w['accuracy'])}"))
    return rows


SUMMARY_HEAD = ("task", "n", "accuracy %", "95 % CI (seed 1st)", "balanced %", "macro-F1 %",
                "worst object %")


def render_markdown(doc: dict[str, Any], figures: list[str]) -> str:
    """report.md: the summary, direction metrics, per-object accuracy, confusion matrices."""
    sub = doc["submission"]
    lines = [f"# Evaluation: {sub['method'] or sub['file']}", "",
             f"- dataset: {doc['dataset']['name']} {doc['dataset']['dataset_version']} "
             f"(sha256 {doc['dataset']['dataset_sha256'][:12]})",
             f"- split: {doc['split']} / {doc['part']} ({doc['n_samples']} {doc['kind']} samples)",
             f"- submission: {sub['file']} (sha256 {sub['sha256'][:12]}), seeds "
             f"{', '.join(map(str, sub['seeds']))}",
             f"- metric version {doc['metric_version']}, vtsbench {doc['vtsbench_version']}", "",
             "| " + " | ".join(SUMMARY_HEAD) + " |", "|---" * len(SUMMARY_HEAD) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in summary_rows(doc)]
    d = doc["tasks"].get("direction")
    if d:
        s = d["summary"]
        r0 = d["runs"][0]

        def f(m: str) -> str:
            return pct(s[m]["mean"])

        mae = s["mean_abs_angular_error_deg"]["mean"]
        lines += ["", "## Direction (on the truly slipping sequences)", "",
                  f"- state given: {f('accuracy')} %; end to end (a wrong state is a miss): "
                  f"{f('end_to_end_accuracy')} %",
                  f"- within one bin: {f('within_one_bin')} %; mean absolute angular error: "
                  f"{'-' if mae is None else f'{mae:.1f}'} degrees",
                  f"- share of errors on the adjacent bin: {f('adjacent_error_share')} %",
                  f"- errors by bins off (0..4, seed {r0['seed']}): {r0['error_bins']}"]
        if r0.get("by_magnitude"):
            lines += ["", f"Direction by slip distance (state given, seed {r0['seed']}):", ""]
            lines += magnitude_table(r0["by_magnitude"])
    st = doc["tasks"].get("state")
    if st and st["runs"][0].get("per_state"):
        lines += ["", f"State accuracy per true state (seed {st['runs'][0]['seed']}): " + "; ".join(
            f"{k} {pct(v['accuracy'])} % (n {v['n']})"
            for k, v in st["runs"][0]["per_state"].items())]
    for task, t in doc["tasks"].items():
        r0 = t["runs"][0]
        lines += ["", f"## {task}: per object (seed {r0['seed']})", "",
                  "| object | n | accuracy % |", "|---|---:|---:|"]
        lines += [f"| {o} | {v['n']} | {pct(v['accuracy'])} |"
                  for o, v in r0["per_object"].items()]
        labels = [_label(task, i, n) for i, n in enumerate(r0["labels"])]
        lines += ["", f"Confusion (rows true, columns predicted; seed {r0['seed']}):", "",
                  "| true \\ pred | " + " | ".join(labels) + " |", "|---" * (len(labels) + 1) + "|"]
        lines += [f"| {labels[i]} | " + " | ".join(map(str, row)) + " |"
                  for i, row in enumerate(r0["confusion"])]
    if figures:
        lines += ["", "## Figures", ""] + [f"![{p}]({p})" for p in figures]
    return "\n".join(lines) + "\n"


def magnitude_table(bm: dict[str, Any]) -> list[str]:
    """Markdown rows of a `by_magnitude` result: bin in mm, pixels at the input, n, accuracy."""
    def px(v: float | None) -> str:
        return "-" if v is None else f"{v:.1f}"

    rows = ["| slip mm | px at the model's input (min / median / max) | n | direction % |",
            "|---|---|---:|---:|"]
    for b in bm["bins"]:
        hi = "inf" if b["hi_mm"] is None else f"{b['hi_mm']:g}"
        rows.append(f"| [{b['lo_mm']:g}, {hi}) | {px(b['px_min'])} / {px(b['px_median'])} / "
                    f"{px(b['px_max'])} | {b['n']} | {pct(b['accuracy'])} |")
    return rows


def _label(task: str, i: int, name: str) -> str:
    return f"{ARROWS[i]} {COMPASS[i]}" if task == "direction" else name


def figure_title(doc: dict[str, Any], task: str, n: int) -> str:
    """A figure's title: what was scored (method, split, part) and on how many samples."""
    sub = doc.get("submission", {})
    method = sub.get("method") or sub.get("file") or "submission"
    return f"{method}: {task} on {doc['split']}/{doc['part']}, n = {n}"


def write_figures(doc: dict[str, Any], out: Path) -> list[str]:
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
    for task, t in doc["tasks"].items():
        r0 = t["runs"][0]
        cm = np.asarray(r0["confusion"], dtype=float)
        labels = [_label(task, i, n) for i, n in enumerate(r0["labels"])]
        with np.errstate(invalid="ignore", divide="ignore"):
            norm = cm / cm.sum(1, keepdims=True)
        k = len(labels)
        side = 2.0 + 0.5 * k
        with print_style():
            fig = Figure(figsize=(2 * side + 0.6, side + 0.8))
            FigureCanvasAgg(fig)
            fig.subplots_adjust(left=0.14, right=0.98, bottom=0.2, top=0.84, wspace=0.45)
            fig.suptitle(figure_title(doc, task, int(cm.sum())), fontsize=FONT + 2)
            for col, (kind, mat) in enumerate((("counts", cm), ("row-normalised", norm))):
                ax = fig.add_subplot(1, 2, col + 1)
                show = np.nan_to_num(mat)
                top = max(float(show.max()), 1e-9)
                ax.imshow(show, cmap="Blues", vmin=0, vmax=top if col == 0 else 1.0)
                ax.set_xticks(range(k), labels, rotation=0 if task == "direction" else 90,
                              fontsize=FONT)
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


def evaluate(submission: str | Path, dataset: str | Path, split: str, part: str = "test",
             out: str | Path | None = None, meta: str | Path | None = None,
             figures: bool = True) -> tuple[dict[str, Any], Submission, Truth]:
    """Validate, score and (when out is given) write metrics.json, report.md and PNGs."""
    truth = load_truth(dataset, split, part)
    sub = load_submission(submission, truth, meta)
    doc = score(truth, sub, slip_motion(dataset, truth.ids) if truth.kind == "slip" else None)
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        names = write_figures(doc, out) if figures else []
        write_text_atomic(out / "metrics.json", json.dumps(doc, indent=1) + "\n")
        write_text_atomic(out / "report.md", render_markdown(doc, names))
    return doc, sub, truth
