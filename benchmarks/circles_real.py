"""Detected contact circles against the labelled ones on the real ball presses, per press.

For Taxim's GelSight presses and the DIGIT presses of ../shared/data/real (skipped when absent):
the label, the detected circle, their centre distance, the radius error (also after the clamp
to 0.97 ball radii that every circle gets, see `sphere.Rim`), whether the label is clamped, and
the consistent centre (`depth.centres.consistent_centres`, started from the labels; only for a
set of at least `centres.MIN_PRESSES` presses) with its distance to the label and the detection.

With --rmse, also the held-out plane-aligned RMSE (poly, a fifth held out, seeds 0-2 pooled,
the same held-out presses) of calibrations trained with the labelled and with the detected
circles, both scored against the labels and, where there are consistent centres, against the
sphere drawn at them (label radius).

With --scales 2.5,4, every press and its background upscaled (bicubic) by each factor and its
circle detected again: the centre's distance to the 1x detection and the radius ratio, in 1x
pixels (does the detector hold at a sensor's full resolution, where a contact spans 40-70 px?).

With --speed, the time of detecting every press's circle with and without the restarts
(`detect_circle(restarts=...)`, alternated, best of 3) and of one `calibrate --circles detect`.

    .venv/bin/python benchmarks/circles_real.py [--digit-px-per-mm 21.09] [--all] [--rounds 4]
                                                [--rmse] [--speed] [--scales 2.5,4]
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from pathlib import Path

import numpy as np

NAMES = {"label": "labelled", "detect": "detected"}
REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"


def label_frame(lab: np.ndarray, det: np.ndarray) -> tuple[float, float]:
    """Labels read as drawn in a frame scaled and shifted from the image's (det = s lab + t:
    one scale, a shift per axis): the scale fitted to every press, and the share of detections
    within 3 px of their label carried by a frame fitted to the other presses alone (a
    diagnostic of the labelling; nothing uses it)."""
    def fit(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        n = len(a)
        m = np.zeros((2 * n, 3))
        m[:n, 0], m[n:, 0], m[:n, 1], m[n:, 2] = a[:, 0], a[:, 1], 1.0, 1.0
        return np.linalg.lstsq(m, np.r_[b[:, 0], b[:, 1]], rcond=None)[0]

    hits = []
    for i in range(len(lab)):
        keep = np.arange(len(lab)) != i
        s, tx, ty = fit(lab[keep], det[keep])
        hits.append(np.hypot(*(s * lab[i] + (tx, ty) - det[i])) <= 3)
    return float(fit(lab, det)[0]), float(np.mean(hits))


def recordings(tmp: Path, digit_px_per_mm: float) -> list[tuple[str, Path, dict]]:
    """(name, recordings folder, load_presses options) of each real set present."""
    from typer.testing import CliRunner

    from vtsbench.cli import app
    from vtsbench.depth.calibration import taxim_recordings

    out = []
    npz = REAL / "taxim_gelsight_ball" / "dataPack_small.npz"
    if npz.is_file():
        out.append(("taxim", taxim_recordings(npz, tmp / "taxim"), {}))
    digit = REAL / "digit_ball_6mm"
    if (digit / "sphere.csv").is_file():
        res = CliRunner().invoke(app, ["manifest", str(digit), "--pattern", "{name}.png",
                                       "--kind", "press", "--ball-radius-mm", "3", "--circles",
                                       str(digit / "sphere.csv"), "--out", str(tmp / "digit")])
        if res.exit_code != 0:
            raise SystemExit(res.output)
        out.append(("digit", tmp / "digit", {"mm_per_px": 1 / digit_px_per_mm,
                                             "estimate_background": True}))
    return out


def reference(folder: Path, opts: dict, rounds: int) -> dict[str, tuple[float, float]]:
    """Consistent centres started from the labels, by press id ({} for too few presses)."""
    from vtsbench.depth.calibration import load_presses
    from vtsbench.depth.centres import MIN_PRESSES, consistent_centres

    presses, bg, setup, _ = load_presses(folder, circles="label", **opts)
    presses = [p for p in presses if p.circle_source == "label"]
    if len(presses) < MIN_PRESSES:
        return {}
    got = consistent_centres(presses, bg, setup, rounds=rounds)
    return {p.id: c for p, c in zip(presses, got, strict=True)}


def rows(folder: Path, opts: dict, ref: dict[str, tuple[float, float]]) -> list[dict]:
    """Per press: id, status, label, detected circle, reference centre and the distances."""
    from vtsbench.depth.calibration import load_presses
    from vtsbench.depth.sphere import Rim, ball_radius_px

    _, _, setup, _ = load_presses(folder, circles="detect", **opts)
    ball = ball_radius_px(setup["ball_radius_mm"], setup["mm_per_px"])
    clamp = Rim().max_radius_frac * ball
    out = []
    for p in setup["presses"]:
        lab, det, c = p["label"], p["detected"], ref.get(p["id"])
        row = {"id": p["id"], "status": p["status"], "label": lab, "detected": det, "ref": c,
               "clamped": lab is not None and lab["r"] > clamp, "ball_px": ball}
        if lab is not None and det is not None:
            row["centre_px"] = math.hypot(det["x"] - lab["x"], det["y"] - lab["y"])
            row["radius_err"] = det["r"] / lab["r"] - 1
            row["radius_err_clamped"] = min(det["r"], clamp) / lab["r"] - 1
        if c is not None and det is not None:
            row["det_ref"] = math.hypot(det["x"] - c[0], det["y"] - c[1])
            row["lab_ref"] = math.hypot(lab["x"] - c[0], lab["y"] - c[1])
        out.append(row)
    return out


def fmt(c: dict | None) -> str:
    return "-" if c is None else f"({c['x']:6.1f}, {c['y']:6.1f}) r {c['r']:4.1f}"


def table(name: str, rs: list[dict], show_all: bool) -> None:
    print(f"\n{name}: ball {rs[0]['ball_px']:.1f} px; centres in px, radii against the label")
    print(f"{'press':>10} {'status':>8} {'label':>23} {'detected':>23} {'det-lab':>7} "
          f"{'radius':>7} {'clamped':>7} {'consistent centre':>17} {'det-ref':>7} "
          f"{'lab-ref':>7} label clamped")
    bad = 0
    for r in rs:
        if r["clamped"] and not show_all:
            continue
        c = r.get("centre_px")
        far = c is not None and not r["clamped"] and (c > 3 or abs(r["radius_err_clamped"]) > .1)
        bad += far
        cells = ["-"] * 3 if c is None else [
            f"{c:.2f}", f"{r['radius_err']:+.1%}", f"{r['radius_err_clamped']:+.1%}"]
        ref = "-" if r["ref"] is None else f"({r['ref'][0]:6.1f}, {r['ref'][1]:6.1f})"
        dr = ["-", "-"] if "det_ref" not in r else [f"{r['det_ref']:.2f}", f"{r['lab_ref']:.2f}"]
        print(f"{r['id']:>10} {r['status']:>8} {fmt(r['label']):>23} {fmt(r['detected']):>23} "
              f"{cells[0]:>7} {cells[1]:>7} {cells[2]:>7} {ref:>17} {dr[0]:>7} {dr[1]:>7} "
              f"{'yes' if r['clamped'] else 'no':>7}{'  <-- label: beyond 3 px / 10 %' * far}")
    n = sum(1 for r in rs if r["label"] is not None and not r["clamped"])
    print(f"{name}: {bad} of {n} unclamped labels beyond 3 px or 10 % of the detection")
    # A label convention (a constant offset) is not a per-press error: the mean offset, and how
    # many centres lie within 3 px once it is taken off (a diagnostic; nothing uses it).
    have = [r for r in rs if "centre_px" in r]
    v = np.array([(r["detected"]["x"] - r["label"]["x"], r["detected"]["y"] - r["label"]["y"])
                  for r in have])
    if len(v):
        mean = v.mean(axis=0)
        raw, off = (np.hypot(*v.T) <= 3).mean(), (np.hypot(*(v - mean).T) <= 3).mean()
        print(f"{name}: detection - label, mean ({mean[0]:+.2f}, {mean[1]:+.2f}) px, sd "
              f"({v[:, 0].std():.2f}, {v[:, 1].std():.2f}); within 3 px {raw:.0%}, "
              f"{off:.0%} with the mean offset taken off")
        lab = np.array([(r["label"]["x"], r["label"]["y"]) for r in have])
        scale, within = label_frame(lab, lab + v)
        print(f"{name}: labels as a frame scaled by {scale:.4f} and shifted: {within:.0%} within "
              f"3 px when each press's frame is fitted to the other presses (leave-one-out)")


def held_out_rmse(folder: Path, opts: dict, ref: dict[str, tuple[float, float]],
                  seeds: tuple[int, ...] = (0, 1, 2)
                  ) -> dict[str, float | tuple[float, float]]:
    """Mean held-out plane-aligned RMSE (mm) per (circles trained with, circles scored with),
    the number of held-out presses, and the 95 % interval of the detected / labelled ratio."""
    from dataclasses import replace

    import numpy as np

    from vtsbench.depth.calibration import calibrate, evaluate_press, load_presses

    labelled = {p.id: p for p in load_presses(folder, circles="label", **opts)[0]
                if p.circle_source == "label"}
    errs: dict[str, list[float]] = {}
    for seed in seeds:
        runs = {c: calibrate(folder, method="poly", seed=seed, circles=c, **opts)
                for c in ("label", "detect")}
        ids = [[h.press.id for h in r.held_out] for r in runs.values()]
        if ids[0] != ids[1]:
            raise SystemExit(f"seed {seed}: the two runs hold out different presses")
        for c, run in runs.items():
            for h in run.held_out:
                lab = labelled.get(h.press.id)
                if lab is None:
                    continue
                scored = {"labels": lab}
                if h.press.id in ref:
                    x, y = ref[h.press.id]
                    scored["consistent centres"] = replace(lab, x=x, y=y)
                for how, press in scored.items():
                    e = evaluate_press(run.calibration, press).errors["plane_aligned_rmse_mm"]
                    errs.setdefault(f"trained on {NAMES[c]} circles, scored against {how}",
                                    []).append(e)
    out = {k: float(np.mean(v)) for k, v in errs.items()} | {
        "held-out presses": float(len(errs[next(iter(errs))]))}
    pair = [errs.get(f"trained on {NAMES[c]} circles, scored against labels")
            for c in ("label", "detect")]
    if pair[0] and pair[1]:
        out["ratio 95% interval"] = ratio_interval(np.array(pair[1]), np.array(pair[0]))
    return out


def ratio_interval(detected: np.ndarray, labelled: np.ndarray, draws: int = 10000,
                   seed: int = 0) -> tuple[float, float]:
    """A paired bootstrap 95 % interval of mean(detected) / mean(labelled) over held-out
    presses (the same press resampled in both, with the evaluation's seeded resampling): how
    far a ratio over a handful of presses can be trusted."""
    from vtsbench.evaluation.metrics import bootstrap_indices, interval

    idx = bootstrap_indices(detected.size, reps=draws, seed=seed)
    lo, hi = interval(detected[idx].mean(axis=1) / labelled[idx].mean(axis=1))
    return lo, hi


def speed(folder: Path, opts: dict, repeats: int = 3) -> str:
    """Detection time per press with and without restarts, and one calibration's time."""
    from vtsbench.depth.calibration import calibrate, load_presses
    from vtsbench.depth.sphere import ball_radius_px, detect_circle

    presses, bg, setup, _ = load_presses(folder, **opts)
    ball = ball_radius_px(setup["ball_radius_mm"], setup["mm_per_px"])
    best = {True: float("inf"), False: float("inf")}
    for _ in range(repeats):
        for restarts in (False, True):
            t0 = time.perf_counter()
            for p in presses:
                detect_circle(p.image, bg, ball_px=ball, restarts=restarts)
            best[restarts] = min(best[restarts], time.perf_counter() - t0)
    t0 = time.perf_counter()
    calibrate(folder, method="poly", circles="detect", **opts)
    cal = time.perf_counter() - t0
    n = len(presses)
    return (f"detection of {n} circles: {best[False] / n * 1e3:.1f} ms a press without restarts, "
            f"{best[True] / n * 1e3:.1f} ms with ({best[True] / best[False]:.1f} x); "
            f"calibrate --circles detect (poly): {cal:.1f} s")


def scales(folder: Path, opts: dict, factors: list[float]) -> list[str]:
    """Per factor: how far the upscaled detections lie from the 1x ones (centre, radius)."""
    import cv2
    import numpy as np

    from vtsbench.depth.calibration import load_presses
    from vtsbench.depth.sphere import ball_radius_px, detect_circle

    presses, bg, setup, _ = load_presses(folder, **opts)
    ball = ball_radius_px(setup["ball_radius_mm"], setup["mm_per_px"])
    base = [detect_circle(p.image, bg, ball_px=ball) for p in presses]
    out = []
    for f in factors:
        def up(a: np.ndarray, f: float = f) -> np.ndarray:
            return cv2.resize(a, None, fx=f, fy=f, interpolation=cv2.INTER_CUBIC)

        big, d, ratio, lost = up(bg), [], [], 0
        for p, b in zip(presses, base, strict=True):
            g = detect_circle(up(p.image), big, ball_px=ball * f)
            if g is None or b is None:
                lost += g is None and b is not None
                continue
            x, y = ((g[0] + 0.5) / f - 0.5, (g[1] + 0.5) / f - 0.5)  # pixel centres
            d.append(math.hypot(x - b[0], y - b[1]))
            ratio.append(g[2] / f / b[2])
        d_, r_ = np.array(d), np.array(ratio)
        out.append(f"x{f:g}: {len(d)} presses, {lost} lost; centre from the 1x detection median "
                   f"{np.median(d_):.2f}, max {d_.max():.2f} px (1x px), {int((d_ > 1).sum())} "
                   f"beyond 1 px; radius x{np.median(r_):.3f} (x{r_.min():.3f}-x{r_.max():.3f})")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--digit-px-per-mm", type=float, default=21.09)
    ap.add_argument("--all", action="store_true", help="also list presses with clamped labels")
    ap.add_argument("--rounds", type=int, default=4, help="rounds of the consistent centres")
    ap.add_argument("--rmse", action="store_true", help="held-out depth error, both circles")
    ap.add_argument("--speed", action="store_true", help="detection time, restarts or not")
    ap.add_argument("--scales", default="", help="upscale factors to detect at, e.g. 2.5,4")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        for name, folder, opts in recordings(Path(tmp), args.digit_px_per_mm):
            t0 = time.perf_counter()
            ref = reference(folder, opts, args.rounds)
            took = time.perf_counter() - t0
            table(name, rows(folder, opts, ref), args.all)
            if ref:
                print(f"{name}: consistent centres ({args.rounds} rounds) in {took:.1f} s")
            else:
                print(f"{name}: too few presses for consistent centres")
            if args.scales:
                for line in scales(folder, opts, [float(f) for f in args.scales.split(",")]):
                    print(f"{name}: {line}")
            if args.speed:
                print(f"{name}: {speed(folder, opts)}")
            if args.rmse:
                for k, v in held_out_rmse(folder, opts, ref).items():
                    shown = ("{:.2f}-{:.2f}x".format(*v) if isinstance(v, tuple)
                             else f"{v:.4f} mm" if "scored" in k else f"{v:.0f}")
                    print(f"{name}: {k}: {shown}")


if __name__ == "__main__":
    main()
