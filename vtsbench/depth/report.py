"""The calibration report: a PNG of the held-out presses, a contact sheet of every press's
circle, and a JSON of their errors.

For each shown press (the held-out ones; with `--holdout 0`, a few training presses, marked so)
one row: the press frame around the contact, the reference depth (simulated truth, or the
sphere model inside the circle), the reconstruction, the error after removing its best plane
over the contact (what the plane-aligned RMSE measures), and the profiles along the row through
the circle's centre (reference and plane-aligned reconstruction).

circles.png (`contact_sheet`): every press, used or dropped, as a tile around its circle, the
labelled circle and the detected one drawn in their own colours (the one used thicker), and under
each tile its status and why: a bad circle shows in seconds.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from ..figures import plain_text
from .calibration import CalibrationRun, HeldOut

MAX_ROWS = 8


def _plane_removed(pred: np.ndarray, true: np.ndarray, region: np.ndarray) -> np.ndarray:
    """pred minus the least-squares plane of (pred - true) over the region (whole frame)."""
    ys, xs = np.nonzero(region)
    if ys.size < 3:
        return pred.astype(np.float64)
    e = (pred - true)[region].astype(np.float64)
    a = np.column_stack([np.ones(ys.size), xs, ys])
    c, *_ = np.linalg.lstsq(a, e, rcond=None)
    h, w = pred.shape
    yy, xx = np.mgrid[0:h, 0:w]
    return pred - (c[0] + c[1] * xx + c[2] * yy)


def _box(h_: HeldOut, shape: tuple[int, int]) -> tuple[int, int, int, int]:
    p = h_.press
    half = math.ceil(max(1.7 * p.r, 8))
    y0, y1 = max(0, int(p.y) - half), min(shape[0], int(p.y) + half + 1)
    x0, x1 = max(0, int(p.x) - half), min(shape[1], int(p.x) + half + 1)
    return y0, y1, x0, x1


#: Agreement of a detected circle with its label: centres within this many pixels, radii
#: within this fraction (after the clamp below the ball both get).
AGREE_PX, AGREE_RADIUS = 3.0, 0.10


def circles_vs_labels(rows: list[dict[str, Any]]) -> dict[str, Any] | None:
    """Detected against labelled circles over the labelled presses whose circle was detected
    (`--circles detect`): medians and the shares within AGREE_PX and AGREE_RADIUS; a labelled
    press where nothing was detected counts as outside both. None when no press has both."""
    labelled = [r for r in rows if r.get("label") is not None]
    compared = [r for r in labelled if r.get("source") == "detected"]
    if not compared or not any("label_offset_px" in r for r in compared):
        return None
    off = np.array([r.get("label_offset_px", np.inf) for r in compared])
    rad = np.array([r.get("label_radius_error", np.inf) for r in compared])
    found = np.isfinite(off)
    near, close = off <= AGREE_PX, np.abs(rad) <= AGREE_RADIUS
    far = sorted((o, r["id"]) for o, r in zip(off, compared, strict=True)
                 if np.isfinite(o) and o > AGREE_PX)
    return {"presses": len(compared), "detected": int(found.sum()),
            "beyond_px": [i for _o, i in far[::-1]],  # farthest first
            "centre_median_px": float(np.median(off[found])),
            "centre_max_px": float(off[found].max()),
            "radius_median": float(np.median(rad[found])),
            "within_px": AGREE_PX, "within_radius": AGREE_RADIUS,
            "share_centre": float(near.mean()), "share_radius": float(close.mean()),
            "share_both": float((near & close).mean())}


def summary(run: CalibrationRun) -> dict[str, Any]:
    """The report's JSON: method, fit statistics and the shown presses' errors (mm)."""
    cal = run.calibration
    rows = [{"id": r.press.id, "held_out": r.held_out, "reference": r.reference,
             "circle": {"x": r.press.x, "y": r.press.y, "r": r.press.r,
                        "source": r.press.circle_source},
             **{k: (None if not math.isfinite(v) else v) for k, v in r.errors.items()},
             "by_solver": {s: {k: (None if not math.isfinite(v) else v) for k, v in e.items()}
                           for s, e in r.by_solver.items()}}
            for r in run.shown]
    return {"method": cal.method, "params": cal.mapping.params, "sensor": cal.sensor,
            "resolution": list(cal.resolution), "mm_per_px": list(cal.mm_per_px),
            "n_presses": cal.n_presses, "seconds": round(run.seconds, 2),
            "train_gradient_rmse": cal.fit.get("train_gradient_rmse"),
            "holdout_mean": cal.fit.get("holdout_mean", {}), "presses": rows,
            "circles": run.presses, "circles_vs_labels": circles_vs_labels(run.presses),
            "dropped": run.dropped, "doubted": run.doubted,
            "retried": run.retried,
            "warnings": run.warnings}


@plain_text
def write_report(run: CalibrationRun, folder: str | Path) -> tuple[Path, Path]:
    """Write report.png and report.json into folder; returns their paths."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from ..atomic import write_text_atomic
    from ..figures import MIN_FONT_PT as FONT
    from ..figures import PRINT_DPI, save_png

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    js = folder / "report.json"
    write_text_atomic(js, json.dumps(summary(run), indent=1, allow_nan=False) + "\n")

    rows = run.shown[:MAX_ROWS]
    cal = run.calibration
    fig = Figure(figsize=(15, 2.7 * max(1, len(rows)) + 0.6), dpi=PRINT_DPI)
    FigureCanvasAgg(fig)
    title = (f"{cal.method} calibration of {cal.sensor}: "
             f"{'held-out' if rows and rows[0].held_out else 'training'} presses "
             f"(plane-aligned RMSE over the contact, mm)")
    fig.suptitle(title, fontsize=11)
    if not rows:
        fig.text(0.5, 0.5, "no presses to show", ha="center")
    for i, r in enumerate(rows):
        y0, y1, x0, x1 = _box(r, cal.resolution)
        true, pred = r.true_depth, _plane_removed(r.pred_depth, r.true_depth, r.region)
        err = np.where(r.region, pred - true, np.nan)[y0:y1, x0:x1]
        vmax = max(float(true.max()), float(pred[y0:y1, x0:x1].max()), 1e-3)
        axes = [fig.add_subplot(len(rows), 5, 5 * i + k + 1) for k in range(5)]
        axes[0].imshow(r.press.image[y0:y1, x0:x1])
        axes[0].set_title(f"{r.press.id} ({r.press.circle_source} circle)", fontsize=FONT)
        axes[1].imshow(true[y0:y1, x0:x1], vmin=0, vmax=vmax, cmap="viridis")
        axes[1].set_title(f"reference ({r.reference}), max {true.max():.3f} mm", fontsize=FONT)
        im = axes[2].imshow(pred[y0:y1, x0:x1], vmin=0, vmax=vmax, cmap="viridis")
        axes[2].set_title("reconstructed (plane-aligned)", fontsize=FONT)
        fig.colorbar(im, ax=axes[2], fraction=0.046, label="mm")
        lim = max(float(np.nanmax(np.abs(err))) if np.isfinite(err).any() else 0.0, 1e-3)
        im = axes[3].imshow(err, vmin=-lim, vmax=lim, cmap="coolwarm")
        axes[3].set_title(f"error, RMSE {r.errors['plane_aligned_rmse_mm']:.4f} mm", fontsize=FONT)
        fig.colorbar(im, ax=axes[3], fraction=0.046, label="mm")
        for ax in axes[:4]:
            ax.set_xticks([])
            ax.set_yticks([])
        row = min(max(round(r.press.y), 0), cal.resolution[0] - 1)
        xs = np.arange(x0, x1) * cal.mm_per_px[0]
        axes[4].plot(xs, true[row, x0:x1], label="reference", color="k")
        axes[4].plot(xs, pred[row, x0:x1], label="reconstructed", color="tab:orange")
        axes[4].axvspan((r.press.x - r.press.r) * cal.mm_per_px[0],
                        (r.press.x + r.press.r) * cal.mm_per_px[0], color="0.9")
        axes[4].invert_yaxis()
        axes[4].set_xlabel("x (mm)", fontsize=FONT)
        axes[4].set_ylabel("depth (mm)", fontsize=FONT)
        axes[4].tick_params(labelsize=FONT)
        axes[4].set_title(f"profile through the centre (row {row})", fontsize=FONT)
        if i == 0:
            axes[4].legend(fontsize=FONT)
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    png = save_png(fig, folder / "report.png")
    contact_sheet(run, folder / "circles.png")
    return png, js


#: Contact sheet colours: the labelled circle, the detected one, and the status of a press.
LABEL_COLOUR, DETECTED_COLOUR = "cyan", "magenta"
STATUS_COLOUR = {"used": "black", "doubted": "darkorange", "dropped": "red"}
SHEET_COLS = 8


def _tile_box(rec: dict[str, Any], shape: tuple[int, int]) -> tuple[int, int, int, int]:
    """(y0, y1, x0, x1): a square around the press's circles (1.8 radii), or around the whole
    frame, which may reach beyond the frame (a contact cut by the border): every tile of the
    sheet is then square, so their captions line up whatever the frame cuts off."""
    cs = [c for c in (rec.get("circle"), rec.get("label"), rec.get("detected")) if c]
    if not cs:
        half = max(shape) // 2
        y, x = shape[0] // 2, shape[1] // 2
    else:
        c = cs[0]
        half = math.ceil(max(1.8 * max(k["r"] for k in cs), 10))
        x, y = round(c["x"]), round(c["y"])
    return y - half, y + half + 1, x - half, x + half + 1


def _tile_text(rec: dict[str, Any], held: set[str]) -> str:
    """The status line and the reasons of a tile, wrapped to its width."""
    import textwrap

    lab, det = rec.get("label"), rec.get("detected")
    status = rec["status"] + (", held out" if rec["id"] in held else "")
    if rec["status"] != "dropped":
        status += f" ({rec['source']})"
    lines = [status]
    if lab and det:
        d = math.hypot(det["x"] - lab["x"], det["y"] - lab["y"])
        lines.append(f"det-label {d:.1f} px, r {det['r'] / lab['r'] - 1:+.0%}")
    elif det:
        lines.append(f"r {det['r']:.1f} px")
    for why in rec.get("reasons", []):
        lines += textwrap.wrap(why, 30)
    if rec.get("retried_after"):
        lines.append("detected again")
    if rec.get("against_presses"):  # under another light: held against presses of its own
        lines.append(f"vs {', '.join(rec['against_presses'][:2])}")
    return "\n".join(lines[:6])


@plain_text
def contact_sheet(run: CalibrationRun, path: str | Path) -> Path:
    """Every press of the run as a tile around its circle: the labelled circle (dashed) and the
    detected one in their own colours, the circle used thicker, status and reasons beneath."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle

    from ..figures import MIN_FONT_PT as FONT
    from ..figures import save_png

    recs = run.presses
    held = {h.press.id for h in run.held_out}
    cols = max(1, min(SHEET_COLS, len(recs)))
    rows = max(1, math.ceil(len(recs) / cols))
    fig = Figure(figsize=(1.9 * cols, 2.75 * rows + 0.7))
    FigureCanvasAgg(fig)
    n_drop = sum(r["status"] == "dropped" for r in recs)
    fig.suptitle(f"{len(recs)} presses, {len(recs) - n_drop} used, {n_drop} dropped; circles: "
                 f"{LABEL_COLOUR} dashed = labelled, {DETECTED_COLOUR} = detected, thick = used",
                 fontsize=FONT + 1)
    top = 0.97
    if run.background_notes:  # a background that is not one spoils every tile: say it here
        import textwrap

        lines = textwrap.wrap(" ".join(run.background_notes),
                              width=max(50, int(11 * 1.9 * cols)))  # ~11 characters an inch
        fig.set_figheight(fig.get_figheight() + 0.17 * len(lines))
        height = fig.get_figheight()
        fig.text(0.5, 1 - 0.3 / height, "\n".join(lines), ha="center", va="top",
                 color=STATUS_COLOUR["dropped"], fontsize=FONT)
        top = 1 - (0.3 + 0.17 * len(lines)) / height
    if not recs:
        fig.text(0.5, 0.5, "no presses", ha="center")
    for i, rec in enumerate(recs):
        ax = fig.add_subplot(rows, cols, i + 1)
        img = run.frames.get(rec["id"])
        ax.set_xticks([])
        ax.set_yticks([])
        colour = STATUS_COLOUR.get(rec["status"], "black")
        ax.set_title(rec["id"], fontsize=FONT, color=colour)
        for side in ax.spines.values():
            side.set_edgecolor(colour)
            side.set_linewidth(2 if rec["status"] != "used" else 0.8)
        if img is not None:
            y0, y1, x0, x1 = _tile_box(rec, img.shape[:2])
            h, w = img.shape[:2]
            cy0, cy1, cx0, cx1 = max(0, y0), min(h, y1), max(0, x0), min(w, x1)
            ax.set_facecolor("0.85")  # beyond the frame
            if cy1 > cy0 and cx1 > cx0:
                ax.imshow(img[cy0:cy1, cx0:cx1],
                          extent=(cx0 - 0.5, cx1 - 0.5, cy1 - 0.5, cy0 - 0.5))
            used = rec.get("circle")
            for key, col, style in (("label", LABEL_COLOUR, "--"), ("detected", DETECTED_COLOUR,
                                                                    "-")):
                c = rec.get(key)
                if not c or c.get("x") is None:
                    continue
                thick = rec["status"] != "dropped" and used == c and rec["source"] == (
                    "label" if key == "label" else "detected")
                ax.add_patch(Circle((c["x"], c["y"]), c["r"], fill=False, color=col,
                                    linestyle=style, linewidth=2.0 if thick else 1.0))
                ax.plot([c["x"]], [c["y"]], "+", color=col, markersize=5)
            ax.set_xlim(x0 - 0.5, x1 - 0.5)
            ax.set_ylim(y1 - 0.5, y0 - 0.5)
        ax.set_xlabel(_tile_text(rec, held), fontsize=FONT - 1, color=colour)
    fig.tight_layout(rect=(0, 0, 1, top))
    return save_png(fig, path)
