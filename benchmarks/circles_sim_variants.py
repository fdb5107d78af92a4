"""Calibration on simulated sensors of other light layouts, with and without a marker gel.

For each light layout of the simulator's optics (`sim.optics.LIGHTS`: three coloured zones, red,
green, blue and white from four sides, near-uniform diffuse light), each gel (the marker gel of
generator 2, and the same gel with no markers printed) and each orientation (landscape 240x320,
portrait 320x240), the same calibration presses of the simulator's 3 mm ball are drawn
(`sim.plan.press_scene`, 0.05 mm/px, the exact truth rendered by `sim.scene.render`) and shot
through the layout and the gel's pattern and camera (`sim.relight.relight`: JPEG, dust, grain,
imprint gain). Per variant, one row: presses used and dropped by `calibrate --circles detect`,
the detected circles against the exact ones (the ball's centre; the radius of a disc of the
contact's area), and the held-out plane-aligned depth RMSE (against the exact depth, over the
contact) of poly calibrations trained on the detected and on the exact circles: every press
held out once, in 4 folds of contiguous presses (--folds 1: the last quarter alone, as before,
a split of 4 presses that can hide a fit's worst press), every variant the same presses. The
marker rows also give their RMSE over that of the same presses without markers (the same gel
with its dots printed with no ink: the same dust, scratches, grain and camera draws).

With --dots, the marker gel's print is another's (dot diameter and pitch in mm, the share of the
light a dot's centre absorbs): small faint dots, or large dense ones. The share is the
simulator's nominal darkness: measured as calibration measures a gel (`markers.background_dots`),
the default print's 75 % passes a median 0.30 of the light within its grown dots, and the real
marker gels of ../shared/data/real 0.48-0.69 (docs/depth.md, other marker prints).

With --deep, circles only: the same ball at a coarser scale (46 px in radius) pressed to
contacts of 0.5, 0.7, 0.85 and 0.95 of its radius (`DEEP_FRACS`), every layout, gel and frame.

    nice -n 15 .venv/bin/python benchmarks/circles_sim_variants.py [--presses 16] [--folds 4]
        [--lights zones3,sides4,uniform] [--method poly] [--seed 0] [--jpeg gel|none|Q|lo-hi]
        [--colour 420|422|444] [--ramp 0.4] [--gain 1.4] [--no-restore] [--dots 0.5,1.6,0.5]
        [--deep | --deep-calibrate]
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from machine import machine  # benchmarks/machine.py: the shared machine line

from vtsbench.sim.optics import LIGHTS

SHAPES = {"landscape": (240, 320), "portrait": (320, 240)}
MM_PER_PX = 0.05
GELS = ("none", "markers")


def render_presses(lights: str, gel: str, shape: tuple[int, int], n: int, seed: int,
                   mm_per_px: float = MM_PER_PX, depths: list[float] | None = None,
                   jpeg: tuple[int, int] | str | None = "gel", ramp: float = 0.0,
                   gain: float = 1.0, dots: tuple[float, float, float] | None = None
                   ) -> tuple[np.ndarray, list[tuple[str, np.ndarray, tuple, object]]]:
    """The background and n presses (id, frame, exact circle, truth) of one layout, gel and
    frame shape; the same scenes and noise draws for every layout and gel. depths: press i
    that deep (mm) instead of a drawn depth. jpeg: the camera's JPEG quality range, None for
    none, "gel" the marker gel's own (60-90). ramp: every frame under coloured side lights
    falling off across the gel (`circles_variants.ramp_light`), 0 for none. gain: every frame
    that much brighter before the ramp, clipped to 8 bits (bright lobes clip). dots: another
    marker print (dot diameter mm, pitch mm, share of the light a dot's centre absorbs)."""
    from circles_variants import ramp_light

    from vtsbench.sim.appearance import background, sensor_appearance
    from vtsbench.sim.optics import Capture, sensor
    from vtsbench.sim.plan import press_scene
    from vtsbench.sim.relight import relight
    from vtsbench.sim.scene import render

    app = sensor_appearance("markers")
    if dots is not None:
        app = dataclasses.replace(app, marker_diameter_mm=dots[0], marker_pitch_mm=dots[1],
                                  marker_darkness=dots[2])
    if jpeg != "gel":
        app = dataclasses.replace(app, jpeg_quality=jpeg)
    if gel == "none":  # the same gel, its dots printed with no ink: the same draws of its
        # dust, scratches and grain (a gel drawn without markers would draw those anew)
        app = dataclasses.replace(app, marker_darkness=0.0)
    fields = sensor(*shape, mm_per_px, lights=lights)
    cap = Capture(gel=seed)
    bg = background(app, fields, cap, np.random.default_rng([seed, 1]))
    if ramp or gain != 1.0:
        bg = ramp_light(bg.astype(np.float32) * gain, ramp)
    out = []
    for i in range(n):
        rng = np.random.default_rng([seed, 2, i])
        scene = press_scene(rng, shape, mm_per_px, 2, app,
                            depth_mm=None if depths is None else depths[i])
        truth = render(scene.with_effects(dataclasses.replace(scene.effects, noise=False)))
        frame = relight(truth.grad, fields, cap, rng, app)[0]
        if ramp or gain != 1.0:
            frame = ramp_light(frame.astype(np.float32) * gain, ramp)
        (cx, cy), r = scene.centers_px[0], math.sqrt(truth.contact[0].sum() / math.pi)
        out.append((f"press-{i:03d}", frame, (cx, cy, r), truth))
    return bg, out


def write_folder(out: Path, bg: np.ndarray, presses: list, sensor: str,
                 mm_per_px: float = MM_PER_PX) -> Path:
    """A recordings folder of presses with their exact circles and truth files."""
    from vtsbench.recordings.manifest import Circle, Entry, Manifest, Session, Source, save_manifest
    from vtsbench.recordings.media import write_png
    from vtsbench.recordings.truth import Truth, write_truth
    from vtsbench.sim.objects import BALL_RADIUS_MM

    (out / "presses").mkdir(parents=True)
    (out / "truth").mkdir()
    write_png(out / "background.png", bg)
    entries = []
    for pid, frame, c, t in presses:
        write_png(out / "presses" / f"{pid}.png", frame)
        write_truth(out / "truth" / f"{pid}.npz", Truth(t.depth_mm, t.grad, t.contact,
                                                        t.motion_px))
        entries.append(Entry(pid, "press", "s0", Source(f"presses/{pid}.png"),
                             object="calibration_ball", ball_radius_mm=BALL_RADIUS_MM,
                             circle=Circle(*c), truth=f"truth/{pid}.npz"))
    h, w = bg.shape[:2]
    save_manifest(out, Manifest(sessions=[Session("s0", sensor, (h, w), (mm_per_px, mm_per_px),
                                                  background="background.png")],
                                entries=entries, name=out.name,
                                created_by="benchmarks/circles_sim_variants.py"))
    return out


def circle_errors(record: list[dict]) -> dict:
    """Used and dropped presses, and the detected circles against the exact ones."""
    dist, rad = [], []
    for p in record:
        lab, det = p["label"], p["detected"]
        if p["status"] != "dropped" and det is not None:
            dist.append(math.hypot(det["x"] - lab["x"], det["y"] - lab["y"]))
            rad.append(det["r"] / lab["r"] - 1)
    d, r = np.array(dist), np.abs(np.array(rad))
    return {"used": len(d), "dropped": len(record) - len(d),
            "centre_med": float(np.median(d)), "centre_max": float(d.max()),
            "radius_med": float(np.median(r)), "radius_max": float(r.max()),
            "good": float(((d <= 3) & (r <= 0.1)).sum() / len(record))}


def dots_arg(text: str) -> tuple[float, float, float]:
    """--dots: "diameter,pitch,darkness" (mm, mm, 0-1)."""
    d, p, k = (float(v) for v in text.split(","))
    if not (0 < d < p and 0 < k <= 1):
        raise argparse.ArgumentTypeError("want 0 < diameter < pitch and 0 < darkness <= 1")
    return d, p, k


def jpeg_arg(text: str) -> tuple[int, int] | str | None:
    """--jpeg: "gel", "none", a quality (90) or a range (60-90)."""
    if text in ("gel", "none"):
        return None if text == "none" else text
    lo, _, hi = text.partition("-")
    return int(lo), int(hi or lo)


def measure(tmp: Path, name: str, bg: np.ndarray, presses: list, held_n: int,
            method: str, folds: int = 1, mm_per_px: float = MM_PER_PX) -> dict:
    """The row of one variant (see the module doc). folds > 1: every press held out once
    (`folds` contiguous blocks), the held-out RMSE the mean over all presses."""
    from vtsbench.depth.calibration import Press, calibrate, evaluate_press, load_presses
    from vtsbench.sim.objects import BALL_RADIUS_MM

    every = write_folder(tmp / f"{name}-all", bg, presses, name, mm_per_px)
    out = circle_errors(load_presses(every, circles="detect")[2]["presses"])
    n = len(presses)
    blocks = [range(n - held_n, n)] if folds <= 1 else \
        [range(f * n // folds, (f + 1) * n // folds) for f in range(folds)]
    errs: dict[str, list[float]] = {"detect": [], "label": []}
    for f, block in enumerate(blocks):
        train = write_folder(tmp / f"{name}-train{f}", bg,
                             [p for i, p in enumerate(presses) if i not in block], name,
                             mm_per_px)
        held = [Press(pid, frame, *c, BALL_RADIUS_MM, "label", every / "truth" / f"{pid}.npz")
                for pid, frame, c, _ in (presses[i] for i in block)]
        for circles in errs:
            run = calibrate(train, method=method, holdout=0, circles=circles, device=None)
            errs[circles] += [evaluate_press(run.calibration, p).errors["plane_aligned_rmse_mm"]
                              for p in held]
            spec = run.calibration.markers
            out["markers"] = "-" if spec is None else \
                f"{spec.n_dots} of {spec.diameter_px:.0f} px"
    out.update({k: float(np.mean(v)) for k, v in errs.items()})
    return out


#: --deep: the ball at this scale (46 px in radius, as on a 320x240 sensor at 19.6 px/mm with
#: a 4.7 mm ball) pressed to contacts of these fractions of its radius, DEEP_PER presses each.
DEEP_MM_PER_PX, DEEP_FRACS, DEEP_PER = 3.0 / 46, (0.5, 0.7, 0.85, 0.95), 4


def deep(lights: list[str], seed: int) -> None:
    """Detection only, on presses as deep as a contact of 0.5-0.95 ball radii: per layout, gel
    and frame, the centre and radius errors against the exact circles, and the presses beyond
    3 px per depth."""
    from vtsbench.depth.sphere import ball_radius_px, detect_circle
    from vtsbench.sim.objects import BALL_RADIUS_MM

    big = BALL_RADIUS_MM
    depths = [big - math.sqrt(big**2 - (f * big) ** 2) for f in DEEP_FRACS for _ in
              range(DEEP_PER)]
    ball = ball_radius_px(big, DEEP_MM_PER_PX)
    print(f"Deep presses: a {big} mm ball at {DEEP_MM_PER_PX:.4f} mm/px ({ball:.0f} px), "
          f"{DEEP_PER} presses at each contact of {', '.join(map(str, DEEP_FRACS))} ball radii\n")
    print("| lights | gel | frame | found | centre error px, median / max | within 3 px | "
          "radius error, median / max | beyond 3 px by contact/ball |")
    print("|---|---|---|---:|---|---:|---|---|")
    for name in lights:
        for gel in GELS:
            for frame, shape in SHAPES.items():
                bg, presses = render_presses(name, gel, shape, len(depths), seed,
                                             DEEP_MM_PER_PX, depths)
                d, r, far = [], [], dict.fromkeys(DEEP_FRACS, 0)
                for i, (_, img, (x, y, rad), _) in enumerate(presses):
                    c = detect_circle(img, bg, ball_px=ball)
                    e = math.inf if c is None else math.hypot(c[0] - x, c[1] - y)
                    d.append(e)
                    r.append(math.inf if c is None else abs(c[2] / rad - 1))
                    far[DEEP_FRACS[i // DEEP_PER]] += e > 3
                fin = [v for v in d if math.isfinite(v)]
                rf = [v for v in r if math.isfinite(v)]
                print(f"| {name} | {gel} | {frame} | {len(fin)} of {len(d)} | "
                      f"{np.median(fin):.2f} / {max(fin):.2f} | "
                      f"{np.mean(np.array(d) <= 3):.0%} | {np.median(rf):.1%} / {max(rf):.1%} | "
                      + ", ".join(f"{f}: {n}" for f, n in far.items()) + " |", flush=True)
    print(f"\nMachine: {machine()}")


def light_note(ramp: float, gain: float, restore: bool) -> str:
    """The run's light and whether a clipped channel is restored, for its first line."""
    return f"light ramp {ramp}, gain {gain}{'' if restore else ', not restored'}"


def circle_cells(lights: str, gel: str, frame: str, r: dict) -> str:
    """The first cells of a row, the same in every table: the variant, presses used and
    dropped, and the circles against the exact ones."""
    return (f"| {lights} | {gel} | {frame} | {r['used']} | {r['dropped']} | "
            f"{r['centre_med']:.2f} / {r['centre_max']:.2f} | "
            f"{r['radius_med']:.1%} / {r['radius_max']:.1%} | {r['good']:.0%} |")


def deep_calibrate(lights: list[str], seed: int, method: str, folds: int,
                   ramp: float = 0.0, gain: float = 1.0, restore: bool = True) -> None:
    """`calibrate --circles detect` end to end (the circles' checks included) on the --deep
    presses, ordered so that every fold holds one press of each contact fraction: presses used
    and dropped, the circles against the exact ones, and the held-out RMSE with detected and
    with exact circles, per layout, gel and frame."""
    from vtsbench.sim.objects import BALL_RADIUS_MM

    big = BALL_RADIUS_MM
    fracs = [f for _ in range(DEEP_PER) for f in DEEP_FRACS]
    depths = [big - math.sqrt(big**2 - (f * big) ** 2) for f in fracs]
    print(f"Deep presses, calibrated: {len(depths)} presses of a {big} mm ball at "
          f"{DEEP_MM_PER_PX:.4f} mm/px, contacts of {', '.join(map(str, DEEP_FRACS))} ball "
          f"radii, each held out once in {folds} folds, {method}, seed {seed}, "
          f"{light_note(ramp, gain, restore)}\n")
    print("| lights | gel | frame | used | dropped | centre error px, median / max | radius "
          "error, median / max | within 3 px and 10 % | held-out RMSE mm, exact circles | "
          "detected | ratio |")
    print("|---|---|---|---:|---:|---|---|---:|---:|---:|---:|")
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for name in lights:
            for gel in GELS:
                for frame, shape in SHAPES.items():
                    bg, presses = render_presses(name, gel, shape, len(depths), seed,
                                                 DEEP_MM_PER_PX, depths, ramp=ramp,
                                                 gain=gain)
                    r = measure(Path(tmp), f"{name}-{frame}-{gel}", bg, presses, 4, method,
                                folds, DEEP_MM_PER_PX)
                    print(f"{circle_cells(name, gel, frame, r)} {r['label']:.4f} | "
                          f"{r['detect']:.4f} | {r['detect'] / r['label']:.2f}x |", flush=True)
    print(f"\nTotal {time.perf_counter() - t0:.0f} s. Machine: {machine()}")


def colour_jpeg(sampling: str) -> None:
    """The simulated camera's JPEG with its colour at another resolution ("422" or "444"):
    the simulator's `camera.jpeg` given that sampling for this run."""
    import functools

    import cv2

    from vtsbench.sim import camera

    flag = {"422": cv2.IMWRITE_JPEG_SAMPLING_FACTOR_422,
            "444": cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444}[sampling]
    camera.jpeg = functools.partial(camera.jpeg, sampling=flag)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--presses", type=int, default=16)
    ap.add_argument("--lights", default=",".join(LIGHTS))
    ap.add_argument("--method", default="poly")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--folds", type=int, default=4,
                    help="hold every press out once in this many blocks (1: the last quarter "
                         "only)")
    ap.add_argument("--jpeg", type=jpeg_arg, default="gel",
                    help="the camera's JPEG quality: gel (the marker gel's own, 60-90), none, a "
                         "quality (90) or a range (60-90)")
    ap.add_argument("--colour", choices=("420", "422", "444"), default="420",
                    help="the camera's JPEG colour resolution: 420 (half each way, libjpeg's "
                         "default), 422 (half across, many USB cameras' MJPEG) or 444 (full)")
    ap.add_argument("--deep", action="store_true",
                    help="circles only, on presses of 0.5-0.95 ball radii (DEEP_FRACS)")
    ap.add_argument("--ramp", type=float, default=0.0,
                    help="coloured side lights falling off across the gel: each channel's light "
                         "1 -/+ this along its own direction (circles_variants.ramp_light)")
    ap.add_argument("--gain", type=float, default=1.0,
                    help="every frame this much brighter (clipped to 8 bits), before --ramp")
    ap.add_argument("--no-restore", action="store_true",
                    help="the change map without a clipped channel restored "
                         "(imprint.restore_clipped), for comparison")
    ap.add_argument("--dots", type=dots_arg, default=None,
                    help="another marker print: dot diameter mm, pitch mm, darkness (the share "
                         "of the light a dot's centre absorbs), e.g. 0.5,1.6,0.5")
    ap.add_argument("--deep-calibrate", action="store_true",
                    help="calibrate end to end on the --deep presses: used, dropped, circles "
                         "and held-out RMSE")
    args = ap.parse_args()
    if args.colour != "420":
        colour_jpeg(args.colour)
    if args.no_restore:
        from vtsbench.depth import imprint

        imprint.restore_clipped = lambda res, image, background: res
    if args.deep:
        deep(args.lights.split(","), args.seed)
        return
    if args.deep_calibrate:
        deep_calibrate(args.lights.split(","), args.seed, args.method, args.folds, args.ramp,
                       args.gain, not args.no_restore)
        return
    held_n = max(1, args.presses // 4)
    held = f"{held_n} held out" if args.folds <= 1 else \
        f"each held out once in {args.folds} folds"
    print(f"{args.presses} simulated presses of a 3 mm ball a variant at {MM_PER_PX} mm/px, "
          f"{held}, {args.method}, seed {args.seed}, JPEG {args.jpeg} colour {args.colour}, "
          f"{light_note(args.ramp, args.gain, not args.no_restore)}"
          + ("" if args.dots is None else ", dots {} mm every {} mm absorbing {}".format(
              *args.dots)) + "\n")
    print("| lights | gel | frame | used | dropped | centre error px, median / max | radius "
          "error, median / max | within 3 px and 10 % | markers found | held-out RMSE mm, "
          "exact circles | detected | ratio | x without markers (exact / detected) | time |")
    print("|---|---|---|---:|---:|---|---|---:|---|---:|---:|---:|---|---:|")
    t_all = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for lights in args.lights.split(","):
            for frame, shape in SHAPES.items():
                plain: dict | None = None
                for gel in GELS:
                    t0 = time.perf_counter()
                    bg, presses = render_presses(lights, gel, shape, args.presses, args.seed,
                                                 jpeg=args.jpeg, ramp=args.ramp,
                                                 gain=args.gain, dots=args.dots)
                    r = measure(Path(tmp), f"{lights}-{frame}-{gel}", bg, presses, held_n,
                                args.method, args.folds)
                    vs = "-" if plain is None else (f"{r['label'] / plain['label']:.2f} / "
                                                    f"{r['detect'] / plain['detect']:.2f}")
                    plain = r if gel == "none" else plain
                    print(f"{circle_cells(lights, gel, frame, r)} "
                          f"{r['markers']} | {r['label']:.4f} | {r['detect']:.4f} | "
                          f"{r['detect'] / r['label']:.2f}x | {vs} | "
                          f"{time.perf_counter() - t0:.0f} s |", flush=True)
    print(f"\nTotal {time.perf_counter() - t_all:.0f} s. Machine: {machine()}")


if __name__ == "__main__":
    main()
