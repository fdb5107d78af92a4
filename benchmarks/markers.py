"""Marker gels: held-out depth error with and without a real marker grid pasted on real presses.

The marker layer is taken from a real marker gel: the first frame of an incipient-slip video
(GelSight Mini, 0.0634 mm/px), its grey level divided by a heavy blur of itself (normalised so
that the gel between the dots is 1, capped at 1), rescaled to the Taxim GelSight's 0.1245 mm/px
(the dots keep their size in mm) and multiplied onto every Taxim press and its background. The
same presses are calibrated without the dots, with them (markers found and filled, the default)
and with them left in (--markers off), and scored against the sphere at the labelled circles;
and once more with the grid moved outward in each labelled contact as a gel flows under a
press (circles_variants.FLOW_AT_RIM of the radius at the rim).

    .venv/bin/python benchmarks/markers.py [--method poly] [--seeds 3]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
from circles_variants import FLOW_AT_RIM, flowed
from machine import machine  # benchmarks/machine.py: the shared machine line

from vtsbench.depth.calibration import calibrate, taxim_recordings

REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"
TAXIM = REAL / "taxim_gelsight_ball" / "dataPack_small.npz"
VIDEO = REAL / "incipient_slip_sample" / "blue_mug" / "exp_num_1" / "camera_0.avi"
MINI_MM_PER_PX, TAXIM_MM_PER_PX = 0.0634, 0.1245


def marker_layer(video: Path, shape: tuple[int, int]) -> np.ndarray:
    """(H, W) transmission of the real marker grid at the Taxim scale, 1 between the dots."""
    import cv2

    cap = cv2.VideoCapture(str(video))
    ok, frame = cap.read()
    cap.release()
    if not ok:
        raise SystemExit(f"cannot read {video}")
    grey = frame.astype(np.float32).mean(-1)
    ratio = grey / cv2.GaussianBlur(grey, (0, 0), 12)
    ratio = np.minimum(ratio / np.median(ratio), 1.0)
    f = MINI_MM_PER_PX / TAXIM_MM_PER_PX
    small = cv2.resize(ratio, None, fx=f, fy=f, interpolation=cv2.INTER_AREA)
    h, w = shape
    if small.shape[0] < h or small.shape[1] < w:
        small = np.pad(small, ((0, max(0, h - small.shape[0])), (0, max(0, w - small.shape[1]))),
                       mode="wrap")
    return small[:h, :w]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--method", default="poly")
    ap.add_argument("--seeds", type=int, default=3)
    args = ap.parse_args()
    if not (TAXIM.is_file() and VIDEO.is_file()):
        raise SystemExit(f"needs {TAXIM} and {VIDEO}")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        with np.load(TAXIM) as z:
            pack = {k: z[k] for k in z.files}
        layer = marker_layer(VIDEO, pack["f0"].shape[:2])
        pasted = dict(pack)
        for k in ("f0", "imgs"):
            pasted[k] = np.clip(np.rint(pack[k] * layer[..., None]), 0, 255).astype(np.uint8)
        np.savez(tmp / "pasted.npz", **pasted)
        # the same grid moved outward in each labelled contact, as a gel flows under a press
        moved = dict(pasted)
        moved["imgs"] = np.stack([
            np.clip(np.rint(img * flowed(layer, (float(c[0]), float(c[1]), float(r)))
                            [..., None]), 0, 255).astype(np.uint8)
            for img, c, r in zip(pack["imgs"], pack["touch_center"],
                                 pack["touch_radius"].reshape(-1), strict=True)])
        np.savez(tmp / "moved.npz", **moved)
        plain = taxim_recordings(TAXIM, tmp / "plain")
        dotted = taxim_recordings(tmp / "pasted.npz", tmp / "dotted")
        flowing = taxim_recordings(tmp / "moved.npz", tmp / "moved")
        for name, folder, markers in (("without markers", plain, "auto"),
                                      ("pasted markers, found and filled", dotted, "auto"),
                                      ("pasted markers, left in (--markers off)", dotted, "off"),
                                      (f"pasted markers moved outward ({FLOW_AT_RIM} r at the "
                                       "rim), found and filled", flowing, "auto")):
            errs, spec = [], None
            for s in range(args.seeds):
                run = calibrate(folder, method=args.method, holdout=9, seed=s, device=None,
                                markers=markers)
                spec = run.calibration.markers
                errs += [h.errors["plane_aligned_rmse_mm"] for h in run.held_out]
            found = "none" if spec is None else f"{spec.n_dots} dots of {spec.diameter_px:.1f} px"
            rows.append((name, float(np.mean(errs)), len(errs), found))
            print(f"{name}: {rows[-1][1]:.4f} mm ({found})", file=sys.stderr)
    print(f"Taxim GelSight, 49 presses, {args.method}, 9 held out, hold-out seeds "
          f"0-{args.seeds - 1} pooled; marker layer from {VIDEO.parent.parent.name}/"
          f"{VIDEO.parent.name}/{VIDEO.name} (dots {layer.min():.2f} of the light at their "
          f"darkest, {(layer < 0.9).mean():.0%} of the frame below 0.9)\n")
    print("| presses | held-out plane-aligned RMSE (mm) | x without markers | markers found |")
    print("|---|---:|---:|---|")
    for name, e, _, found in rows:
        print(f"| {name} | {e:.4f} | {e / rows[0][1]:.2f} | {found} |")
    print(f"\nMachine: {machine()}")


if __name__ == "__main__":
    main()
