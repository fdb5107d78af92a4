"""Circle detection on variants of the real ball presses that no detector setting was tuned on.

Each real press set of ../shared/data/real (Taxim's GelSight npz with its background; the DIGIT
PNGs with sphere.csv, background estimated) is turned, with its labelled circles, into variants
in a temporary folder: as recorded, rotated by 90 degrees (portrait <-> landscape), mirrored,
rescaled by 0.5, 1.5 and 2 (the scale in mm/px follows), JPEG-compressed at quality 75, and with
a real marker grid pasted (the marker layer of the first frame of an incipient-slip video: the
frame over its median of 31 px, resized to the set's scale at 0.0634 mm/px, multiplied onto the
presses and the background), the colour channels swapped (RGB read as BGR), a darker exposure
(0.6 times the light through an 8-bit gamma of 2.2), rotated, with markers, then
JPEG-compressed, in turn, and with markers that move: the grid moved outward in each labelled
contact as a gel flows under a press (FLOW_AT_RIM of the radius at the rim), alone and rotated
then JPEG-compressed; and other cameras: noisier (NOISE_DN), out of focus (BLUR_PX), with a
vignette (VIGNETTE), another white balance (BALANCE) and an auto exposure that brightens the
presses but not the background (EXPOSURE; DIGIT's background is estimated from the presses, so
there every frame is brighter alike); and a marker gel at a higher resolution, where the dots
span more pixels: the grid moved, at 2x, and at 2.5x rotated then JPEG-compressed (a portrait
frame of about 400x300 with contacts of about 42 px); the frame cut by an eighth of each side
(contacts near the edge cut by the border), and coloured side lights that fall off across the
gel (each channel's light a ramp of 1 -/+ RAMP along its own direction, so that bright lobes
clip at 255), a monochrome camera (every channel the grey level), and a camera moved between
the background and the presses (the background shifted by BG_SHIFT px; Taxim alone, DIGIT's
background is estimated from its presses). Any variants joined by
"-" are applied in turn (`--variants x1.25-mirror-noise`).
Per set and variant, one row: presses used and dropped (`calibrate --circles detect`), the detected
circles against the labels (centre distance, median and share within 3 px of the variant's pixels,
and in the set's own pixels; radius error after the 0.97 R clamp both get, median and share within
10 %; the share within both), and the held-out plane-aligned RMSE of poly calibrations trained on
the labelled and on the detected circles (hold-out of a fifth, seeds pooled, the same held-out
presses, scored against the labels; a labelled press that detection drops is left out of both).

Where a detected centre is more than 3 px from its label, a referee that needs neither decides
which one the imprint sides with: the centre about which the change is most point-symmetric
(`depth.centres.symmetric_centre`); "label off" counts the presses where it lies more than 3 px
from the label and within 3 px of the detection.

    .venv/bin/python benchmarks/circles_variants.py [--seeds 0,1,2] [--only taxim,digit]
                                                    [--variants base,rot90,...] [--no-rmse]
    .venv/bin/python benchmarks/circles_variants.py --speed --variants base,markers,x2-moved
    .venv/bin/python benchmarks/circles_variants.py --clip-speed --variants base,ramp,crop-ramp
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from circles_real import REAL, held_out_rmse

VARIANTS = ("base", "rot90", "mirror", "x0.5", "x1.5", "x2", "jpeg75", "markers", "swap", "dim",
            "rot90-markers-jpeg75", "moved", "rot90-moved-jpeg75", "noise", "blur", "vignette",
            "balance", "exposure", "x2-moved", "x2.5-rot90-moved-jpeg75", "crop", "ramp",
            "crop-ramp", "crop-rot90-ramp-jpeg75", "grey", "bgshift", "markers-bgshift")
#: Other cameras: noise (DN, per pixel and channel), defocus (Gaussian sigma, px), corners
#: darkened to this share of the centre's light; a white balance (R, G, B gains) and an auto
#: exposure that makes the presses brighter than the background by this factor.
NOISE_DN, BLUR_PX, VIGNETTE = 4.0, 1.5, 0.6
BALANCE, EXPOSURE = (1.15, 1.0, 0.85), 1.08
#: Coloured side lights: each channel's light a ramp from 1 - RAMP to 1 + RAMP across the frame,
#: each along its own direction (0, 120 and 240 degrees).
RAMP = 0.4
#: A camera moved between the background and the presses: the background shifted by (x, y) px.
BG_SHIFT = (2.0, 1.0)
MARKER_MM_PER_PX = 0.0634  # GelSight Mini at 320x240 (gelsight_mini_objects/gsmini.yaml)
TAXIM_MM_PER_PX, TAXIM_BALL_MM = 0.1245, 2.0
DIGIT_MM_PER_PX, DIGIT_BALL_MM = 1 / 21.09, 3.0

Label = tuple[float, float, float]


class PressSet:
    """Presses, optional background, labels by name, scale: one set or one of its variants."""

    def __init__(self, name: str, images: dict[str, np.ndarray], bg: np.ndarray | None,
                 labels: dict[str, Label], mm_per_px: float, ball_mm: float,
                 factor: float = 1.0,
                 fwd: Callable[[Label], Label] = lambda c: c) -> None:
        self.name, self.images, self.bg, self.labels = name, images, bg, labels
        self.mm_per_px, self.ball_mm, self.factor = mm_per_px, ball_mm, factor
        self.fwd = fwd  # a circle of the set as recorded -> the same circle in this variant

    def map(self, f_img: Callable[[np.ndarray], np.ndarray],
            f_lab: Callable[[Label, tuple[int, int]], Label], scale: float = 1.0) -> PressSet:
        shape = next(iter(self.images.values())).shape[:2]
        return PressSet(self.name, {k: f_img(v) for k, v in self.images.items()},
                        None if self.bg is None else f_img(self.bg),
                        {k: f_lab(v, shape) for k, v in self.labels.items()},
                        self.mm_per_px / scale, self.ball_mm, self.factor * scale,
                        lambda c: f_lab(self.fwd(c), shape))

    def without(self, ids: list[str]) -> PressSet:
        """The same set less the presses `ids`."""
        return PressSet(self.name, {k: v for k, v in self.images.items() if k not in ids},
                        self.bg, {k: v for k, v in self.labels.items() if k not in ids},
                        self.mm_per_px, self.ball_mm, self.factor, self.fwd)


def real_sets() -> list[PressSet]:
    """The real press sets present (Taxim RGB with its background; DIGIT as stored)."""
    import cv2

    out = []
    npz = REAL / "taxim_gelsight_ball" / "dataPack_small.npz"
    if npz.is_file():
        with np.load(npz) as z:
            imgs = {f"press-{i:03d}": a for i, a in enumerate(z["imgs"])}
            labs = {f"press-{i:03d}": (float(c[0]), float(c[1]), float(r))
                    for i, (c, r) in enumerate(zip(z["touch_center"],
                                                   z["touch_radius"].reshape(-1), strict=True))}
            out.append(PressSet("taxim", imgs, z["f0"].copy(), labs, TAXIM_MM_PER_PX,
                                TAXIM_BALL_MM))
    digit = REAL / "digit_ball_6mm"
    if (digit / "sphere.csv").is_file():
        with open(digit / "sphere.csv") as fh:
            labs = {Path(r["img_names"]).stem: (float(r["center_x"]), float(r["center_y"]),
                                                float(r["radius"])) for r in csv.DictReader(fh)}
        imgs = {p.stem: cv2.imread(str(p)) for p in sorted(digit.glob("*.png"))}
        out.append(PressSet("digit", imgs, None, labs, DIGIT_MM_PER_PX, DIGIT_BALL_MM))
    return out


def marker_layer() -> np.ndarray | None:
    """The marker grid of a real marker gel (float32 H x W, 1 off the dots, below on them)."""
    import cv2

    vids = sorted((REAL / "incipient_slip_sample").glob("*/exp_num_*/camera_*.avi"))
    if not vids:
        return None
    cap = cv2.VideoCapture(str(vids[0]))
    ok, frame = cap.read()
    cap.release()
    if not ok:
        return None
    g = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
    return np.clip(g.astype(np.float32) / np.maximum(cv2.medianBlur(g, 31), 1), 0.0, 1.0)


def _u8(a: np.ndarray) -> np.ndarray:
    """Light values rounded to an 8-bit frame (clipped to 0-255)."""
    return np.clip(a, 0, 255).round().astype(np.uint8)


def ramp_light(a: np.ndarray, strength: float = RAMP) -> np.ndarray:
    """A BGR frame under coloured side lights: each channel's light times a ramp from
    1 - strength to 1 + strength across the frame, along its own direction (0, 120, 240
    degrees), clipped to 8 bits."""
    h, w = a.shape[:2]
    yy, xx = np.mgrid[:h, :w]
    u, v = 2 * xx / (w - 1) - 1, 2 * yy / (h - 1) - 1
    gain = np.stack([1 + strength * (np.cos(t) * u + np.sin(t) * v) / math.sqrt(2)
                     for t in np.deg2rad((0.0, 120.0, 240.0))], axis=-1)
    return _u8(a * gain)


def _same(c: Label, hw: tuple[int, int]) -> Label:
    """A circle of a variant that moves no pixel."""
    return c


def variant(s: PressSet, how: str, layer: np.ndarray | None) -> PressSet | None:
    """The variant `how` of a press set (None when it cannot be built here)."""
    import cv2

    if how == "base":
        return s
    if "-" in how:  # several in turn
        for part in how.split("-"):
            v = variant(s, part, layer)
            if v is None:
                return None
            s = v
        return s
    if how == "rot90":  # counter-clockwise: column x, row y -> column y, row W - 1 - x
        return s.map(lambda a: np.ascontiguousarray(np.rot90(a)),
                      lambda c, hw: (c[1], hw[1] - 1 - c[0], c[2]))
    if how == "mirror":
        return s.map(lambda a: np.ascontiguousarray(a[:, ::-1]),
                     lambda c, hw: (hw[1] - 1 - c[0], c[1], c[2]))
    if how.startswith("x"):
        f = float(how[1:])
        interp = cv2.INTER_AREA if f < 1 else cv2.INTER_CUBIC

        def resize(a: np.ndarray) -> np.ndarray:
            h, w = a.shape[:2]
            return cv2.resize(a, (round(w * f), round(h * f)), interpolation=interp)

        return s.map(resize, lambda c, hw: ((c[0] + 0.5) * f - 0.5, (c[1] + 0.5) * f - 0.5,
                                            c[2] * f), scale=f)
    if how == "jpeg75":
        def jpeg(a: np.ndarray) -> np.ndarray:
            _, buf = cv2.imencode(".jpg", a, [cv2.IMWRITE_JPEG_QUALITY, 75])
            return cv2.imdecode(buf, cv2.IMREAD_UNCHANGED)

        return s.map(jpeg, _same)
    if how == "grey":  # a monochrome camera: every channel the frame's grey level
        return s.map(lambda a: np.ascontiguousarray(np.repeat(
            cv2.cvtColor(a, cv2.COLOR_BGR2GRAY)[..., None], 3, axis=-1)), _same)
    if how == "swap":  # the colour channels in the other order (RGB read as BGR)
        return s.map(lambda a: np.ascontiguousarray(a[..., ::-1]), _same)
    if how == "dim":  # a darker exposure: 0.6 times the light, then an 8-bit camera's gamma
        return s.map(lambda a: (255 * (0.6 * (a / 255.0) ** 2.2) ** (1 / 2.2)).round()
                     .astype(np.uint8), _same)
    if how == "noise":  # a noisier camera: Gaussian noise of 4 DN, drawn afresh for each frame
        rng = np.random.default_rng(11)
        return s.map(lambda a: _u8(a + rng.normal(0, NOISE_DN, a.shape)), _same)
    if how == "blur":  # a camera out of focus: a Gaussian of BLUR_PX
        return s.map(lambda a: cv2.GaussianBlur(a, (0, 0), BLUR_PX), _same)
    if how == "vignette":  # a lens that darkens the corners to VIGNETTE of the centre
        def vignette(a: np.ndarray) -> np.ndarray:
            h, w = a.shape[:2]
            yy, xx = np.mgrid[:h, :w]
            rho2 = ((xx - (w - 1) / 2) ** 2 + (yy - (h - 1) / 2) ** 2) / (((w - 1) / 2) ** 2
                                                                        + ((h - 1) / 2) ** 2)
            fall = 1 - (1 - VIGNETTE) * rho2
            return _u8(a * fall[..., None])

        return s.map(vignette, _same)
    if how == "balance":  # another white balance: red up, blue down, every frame alike
        gain = np.array(BALANCE, np.float32)[::-1]  # frames are BGR, as written
        return s.map(lambda a: _u8(a * gain), _same)
    if how == "exposure":  # auto exposure: the presses EXPOSURE times as bright as the background
        out = s.map(lambda a: _u8(a * EXPOSURE), _same)
        return PressSet(out.name, out.images, s.bg, out.labels, out.mm_per_px, out.ball_mm,
                        out.factor, out.fwd)
    if how == "bgshift":  # the camera moved by BG_SHIFT between the background and the presses
        if s.bg is None:
            return None
        move = np.float32([[1, 0, BG_SHIFT[0]], [0, 1, BG_SHIFT[1]]])
        bg = cv2.warpAffine(s.bg, move, s.bg.shape[1::-1], flags=cv2.INTER_LINEAR,
                            borderMode=cv2.BORDER_REFLECT)
        return PressSet(s.name, s.images, bg, s.labels, s.mm_per_px, s.ball_mm, s.factor,
                        s.fwd)
    if how == "crop":  # an eighth of each side cut off: contacts near the edge cut by the border
        def crop(a: np.ndarray) -> np.ndarray:
            h, w = a.shape[:2]
            return np.ascontiguousarray(a[h // 8:h - h // 8, w // 8:w - w // 8])

        return s.map(crop, lambda c, hw: (c[0] - hw[1] // 8, c[1] - hw[0] // 8, c[2]))
    if how == "ramp":  # coloured side lights falling off across the gel, every frame alike
        return s.map(ramp_light, _same)
    if how == "markers":
        if layer is None:
            return None
        lay = _marker_grid(s, layer)[..., None]
        return s.map(lambda a: _u8(a * lay), _same)
    if how == "moved":  # markers that move outward in each labelled contact, as a gel flows
        if layer is None:
            return None
        grid = _marker_grid(s, layer)
        imgs = {k: _u8(a * flowed(grid, s.labels.get(k))[..., None])
                for k, a in s.images.items()}
        return PressSet(s.name, imgs, None if s.bg is None else _u8(s.bg * grid[..., None]),
                        s.labels, s.mm_per_px, s.ball_mm, s.factor, s.fwd)
    raise SystemExit(f"unknown variant {how!r} (use {', '.join(VARIANTS)})")


def _marker_grid(s: PressSet, layer: np.ndarray) -> np.ndarray:
    """The real marker grid at the set's scale and size (the dots keep their size in mm)."""
    import cv2

    h, w = next(iter(s.images.values())).shape[:2]
    k = MARKER_MM_PER_PX / s.mm_per_px
    big = cv2.resize(layer, (max(w, round(layer.shape[1] * k)),
                             max(h, round(layer.shape[0] * k))), interpolation=cv2.INTER_AREA)
    return big[:h, :w]


#: Outward flow of the gel at the contact's rim, as a share of the contact radius (an assumed
#: size: the real marker videos mix shear into every press, so it is not measured from them).
FLOW_AT_RIM = 0.1


def flowed(grid: np.ndarray, circle: Label | None) -> np.ndarray:
    """The marker grid with its dots moved outward in the contact `circle` (x, y, r px): by
    FLOW_AT_RIM r times rho / r inside, falling as (r / rho)^2 outside; unmoved without one."""
    import cv2

    if circle is None:
        return grid
    x, y, r = circle
    h, w = grid.shape
    yy, xx = np.mgrid[:h, :w].astype(np.float32)
    dx, dy = xx - x, yy - y
    rho = np.maximum(np.hypot(dx, dy), 1e-3)
    u = FLOW_AT_RIM * r * np.where(rho <= r, rho / r, (r / rho) ** 2)
    # Inverse map: a pixel shows the dot that sat u closer to the centre.
    return cv2.remap(grid, xx - u * dx / rho, yy - u * dy / rho, cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REFLECT)


def write(s: PressSet, folder: Path) -> tuple[Path, dict]:
    """A recordings folder of the set (labels as its circles); load_presses options."""
    import cv2
    from typer.testing import CliRunner

    from vtsbench.cli import app

    folder.mkdir(parents=True)
    for k, a in s.images.items():
        cv2.imwrite(str(folder / f"{k}.png"), a)
    rows = ["name,center_x,center_y,radius"] + [f"{k},{c[0]!r},{c[1]!r},{c[2]!r}"
                                               for k, c in s.labels.items()]
    (folder / "circles.csv").write_text("\n".join(rows) + "\n")
    rec = folder.parent / (folder.name + "-rec")
    res = CliRunner().invoke(app, ["manifest", str(folder), "--pattern", "{name}.png", "--kind",
                                   "press", "--ball-radius-mm", str(s.ball_mm), "--circles",
                                   str(folder / "circles.csv"), "--out", str(rec)])
    if res.exit_code != 0:
        raise SystemExit(res.output)
    opts: dict = {"mm_per_px": s.mm_per_px}
    if s.bg is None:
        opts["estimate_background"] = True
    else:
        cv2.imwrite(str(folder / "background.png"), s.bg)
        opts["background"] = folder / "background.png"
    return rec, opts


def measure(s: PressSet, rec: Path, opts: dict, seeds: tuple[int, ...] | None,
            base: dict[str, Label] | None = None) -> dict:
    """The row of one set and variant (see the module doc); base: the circles detected on the
    set as recorded, to which the variant's are compared (in the set's pixels)."""
    from vtsbench.depth.calibration import load_presses
    from vtsbench.depth.centres import symmetric_centre
    from vtsbench.depth.sphere import change_map, default_sigma

    presses, bg, setup, _ = load_presses(rec, circles="detect", **opts)
    images = {p.id: p.image for p in presses}
    dist, rad, off, label_off = [], [], [], 0
    for p in setup["presses"]:
        lab, det = p["label"], p["detected"]
        if lab is None or det is None or p["status"] == "dropped":
            continue
        # the calibration's own comparison (`calibration.label_agreement`): the centres'
        # distance, and the radii both clamped below the ball
        d = p["label_offset_px"]
        dist.append(d)
        rad.append(p["label_radius_error"])
        if d > 3 and p["id"] in images:
            off.append(p["id"])
            m = change_map(images[p["id"]], bg, default_sigma(bg.shape[:2]), markers=True)
            sx, sy = symmetric_centre(m, det["x"], det["y"], 1.5 * det["r"])
            label_off += (math.hypot(sx - lab["x"], sy - lab["y"]) > 3
                          and math.hypot(sx - det["x"], sy - det["y"]) <= 3)
    n_lab = sum(p["label"] is not None for p in setup["presses"])
    dist_, rad_ = np.array(dist), np.array(rad)
    row = {"used": len(presses), "dropped": [p["id"] for p in setup["presses"]
                                             if p["status"] == "dropped"],
           "labelled": n_lab, "compared": len(dist),
           "centre_med": float(np.median(dist_)), "centre_med_1x": float(np.median(dist_))
           / s.factor, "within3": float((dist_ <= 3).sum() / n_lab),
           "within3_1x": float((dist_ / s.factor <= 3).sum() / n_lab),
           "radius_med": float(np.median(rad_)), "within10": float((abs(rad_) <= .1).sum() / n_lab),
           "both": float(((dist_ <= 3) & (abs(rad_) <= .1)).sum() / n_lab),
           "beyond3": off, "label_off": label_off,
           "detected": {p["id"]: (p["detected"]["x"], p["detected"]["y"], p["detected"]["r"])
                        for p in setup["presses"] if p["status"] != "dropped"}}
    if base is not None:
        moved = [math.hypot(c[0] - b[0], c[1] - b[1]) / s.factor
                 for k, c in row["detected"].items() if k in base
                 for b in [s.fwd(base[k])]]
        row["to_base"] = (float(np.median(moved)), float(np.max(moved))) if moved else None
    if seeds:
        lost = [k for k in row["dropped"] if k in s.labels]
        if lost:  # labelled presses the detector dropped: both calibrations go without them
            rec, opts = write(s.without(lost), rec.parent / f"{rec.name}-kept")
        r = held_out_rmse(rec, opts, {}, seeds)
        row["rmse_label"] = r["trained on labelled circles, scored against labels"]
        row["rmse_detect"] = r["trained on detected circles, scored against labels"]
        row["held_out"] = int(r["held-out presses"])
        row["ratio_ci"] = r.get("ratio 95% interval")
    return row


def print_row(name: str, how: str, r: dict, took: float) -> None:
    tb = "-" if r.get("to_base") is None else f"{r['to_base'][0]:.2f} / {r['to_base'][1]:.2f}"
    rm = "-" if "rmse_label" not in r else (
        f"{r['rmse_label']:.4f} | {r['rmse_detect']:.4f} | "
        f"{r['rmse_detect'] / r['rmse_label']:.2f}x ({r['held_out']}"
        + ("" if r.get("ratio_ci") is None else ", 95 % {:.2f}-{:.2f}x".format(*r["ratio_ci"]))
        + ")")
    print(f"| {name} | {how} | {r['used']} | {', '.join(r['dropped']) or 'none'} | "
          f"{r['centre_med']:.2f} ({r['centre_med_1x']:.2f}) | {r['within3']:.0%} "
          f"({r['within3_1x']:.0%}) | {r['radius_med']:+.1%} | {r['within10']:.0%} | "
          f"{r['both']:.0%} | {len(r['beyond3'])}: {r['label_off']} label off | {tb} | {rm} | "
          f"{took:.0f} s |", flush=True)


def speed(s: PressSet, how: str, presses: int = 12, rounds: int = 3) -> str:
    """One row: the time of a detection on the first presses of a variant, the usual map alone
    (the blur of `default_sigma`) against the whole detector, which on a marker gel with wide
    dots also finds the circle on a map blurred in proportion to them (`sphere.DOT_SIGMA_DIV`);
    ms a press, best of `rounds` alternated rounds."""
    from vtsbench.depth.sphere import ball_radius_px, default_sigma, detect_circle

    imgs = list(s.images.values())
    bg = s.bg if s.bg is not None else np.median(np.stack(imgs), axis=0).astype(np.uint8)
    ball = ball_radius_px(s.ball_mm, s.mm_per_px)
    imgs = imgs[:presses]
    usual = {"sigma": default_sigma(bg.shape[:2])}
    detect_circle(imgs[0], bg, ball_px=ball)  # the background's dots found once
    best = {"usual": math.inf, "whole": math.inf}
    for _ in range(rounds):
        for name, kw in (("usual", usual), ("whole", {})):
            t0 = time.perf_counter()
            for im in imgs:
                detect_circle(im, bg, ball_px=ball, **kw)
            best[name] = min(best[name], (time.perf_counter() - t0) / len(imgs) * 1000)
    h, w = bg.shape[:2]
    return (f"| {s.name} | {how} | {h}x{w} | {best['usual']:.0f} | {best['whole']:.0f} | "
            f"{best['whole'] / best['usual']:.2f}x |")


def clip_speed(s: PressSet, how: str, presses: int = 12, rounds: int = 3) -> str:
    """One row: the detection time on the first presses of a variant with a clipped channel
    restored from the other two (`imprint.restore_clipped`, as calibration runs it) against
    the same detector without the restoration; ms a press, best of `rounds` alternated
    rounds, and how many of the presses clip in some channel where the background does not."""
    from vtsbench.depth import imprint
    from vtsbench.depth.sphere import ball_radius_px, detect_circle

    imgs = list(s.images.values())
    bg = s.bg if s.bg is not None else np.median(np.stack(imgs), axis=0).astype(np.uint8)
    ball = ball_radius_px(s.ball_mm, s.mm_per_px)
    imgs = imgs[:presses]
    clip = sum(int(((im >= 254) & (bg < 254)).sum() >= imprint.CLIP_MIN_PIXELS) for im in imgs)
    restore = imprint.restore_clipped
    best = {"restored": math.inf, "as recorded": math.inf}
    detect_circle(imgs[0], bg, ball_px=ball)  # warm: the background's dots found once
    try:
        for _ in range(rounds):
            for name in best:
                imprint.restore_clipped = restore if name == "restored" else \
                    (lambda res, image, background: res)
                t0 = time.perf_counter()
                for im in imgs:
                    detect_circle(im, bg, ball_px=ball)
                best[name] = min(best[name], (time.perf_counter() - t0) / len(imgs) * 1000)
    finally:
        imprint.restore_clipped = restore
    h, w = bg.shape[:2]
    return (f"| {s.name} | {how} | {h}x{w} | {clip} of {len(imgs)} | "
            f"{best['as recorded']:.0f} | {best['restored']:.0f} | "
            f"{best['restored'] / best['as recorded']:.2f}x |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,1,2", help="hold-out seeds pooled for the RMSE")
    ap.add_argument("--no-rmse", action="store_true", help="circles only, no calibration")
    ap.add_argument("--only", default="", help="sets, e.g. taxim,digit")
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--speed", action="store_true",
                    help="detection time, the usual map alone against the whole detector")
    ap.add_argument("--clip-speed", action="store_true",
                    help="detection time with a clipped channel restored, against without")
    args = ap.parse_args()
    seeds = None if args.no_rmse else tuple(int(s) for s in args.seeds.split(","))
    sets = [s for s in real_sets() if not args.only or s.name in args.only.split(",")]
    if not sets:
        raise SystemExit(f"no real press sets under {REAL}")
    layer = marker_layer()
    timing = {"clip_speed": (clip_speed, "| set | variant | frame | presses that clip | not "
                                         "restored, ms a press | restored | ratio |\n"
                                         "|---|---|---|---:|---:|---:|---:|"),
              "speed": (speed, "| set | variant | frame | usual map, ms a press | whole "
                               "detector | ratio |\n|---|---|---|---:|---:|---:|")}
    for flag, (row, head) in timing.items():
        if getattr(args, flag):
            print(head)
            for s in sets:
                for how in args.variants.split(","):
                    v = variant(s, how, layer)
                    if v is not None:
                        print(row(v, how), flush=True)
            return
    print("| set | variant | used | dropped | centre - label, median px (set's px) | within 3 px "
          "(set's px) | radius, median | within 10 % | both | beyond 3 px: label off its "
          "imprint | centre - as recorded, median / max (set's px) | held-out RMSE mm, "
          "labelled | detected | ratio (presses) | time |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for s in sets:
            base = None
            for how in args.variants.split(","):
                v = variant(s, how, layer)
                if v is None:
                    why = ("no background to shift (estimated from the presses)"
                           if "bgshift" in how and s.bg is None else "no marker video")
                    print(f"| {s.name} | {how} | not built: {why} |")
                    continue
                t0 = time.perf_counter()
                rec, opts = write(v, Path(tmp) / f"{s.name}-{how}")
                row = measure(v, rec, opts, seeds, base)
                print_row(s.name, how, row, time.perf_counter() - t0)
                if how == "base":
                    base = row["detected"]


if __name__ == "__main__":
    main()
