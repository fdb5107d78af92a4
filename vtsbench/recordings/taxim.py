"""Taxim-style data packs of GelSight ball presses (one .npz) as a recordings folder.

The pack holds the background, the press images and their labelled circles; the folder written
is an ordinary recordings folder of `press` entries that `vtsbench calibrate` fits.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..errors import VtsError
from .manifest import MANIFEST_NAME, Circle, Entry, Manifest, Session, Source, save_manifest
from .media import write_png


def taxim_recordings(npz: str | Path, out: str | Path, *, ball_radius_mm: float = 2.0,
                     mm_per_px: float = 0.1245, sensor: str = "gelsight-taxim") -> Path:
    """A recordings folder for a Taxim-style data pack of GelSight presses, written to out.

    The archive holds the background `f0` (H x W x 3), the presses `imgs` (N x H x W x 3, RGB)
    and their labelled circles (`touch_center` N x 2 as x, y and `touch_radius` N, px). The
    defaults are those of Taxim's `dataPack_small.npz`: a 2 mm-radius ball at 0.1245 mm/px;
    give another pack's ball and scale. Arrays are checked before anything is written, and
    recordings.json last, so an interrupted run never looks complete.
    """
    npz, out = Path(npz), Path(out)
    for name, v in (("ball_radius_mm", ball_radius_mm), ("mm_per_px", mm_per_px)):
        if not (math.isfinite(v) and v > 0):
            raise VtsError(f"{name} must be a positive number, got {v}")
    try:
        with np.load(npz, allow_pickle=False) as z:
            f0, imgs = z["f0"], z["imgs"]
            centre, radius = z["touch_center"], z["touch_radius"]
    except FileNotFoundError:
        raise VtsError("file not found", npz) from None
    except (KeyError, ValueError, OSError, EOFError) as e:
        raise VtsError(f"not a Taxim data pack ({e})", npz) from None
    n = len(imgs) if imgs.ndim == 4 else -1
    problem = (
        "f0 is not an H x W x 3 image" if f0.ndim != 3 or f0.shape[2] != 3 else
        "imgs is not N x H x W x 3 images the size of f0" if imgs.shape[1:] != f0.shape else
        f"touch_center is not {n} x 2" if centre.shape != (n, 2) else
        f"touch_radius is not {n} radii" if radius.reshape(-1).shape != (n,) else
        "the circles hold a NaN or an infinity" if not (np.isfinite(centre).all()
                                                       and np.isfinite(radius).all()) else
        "images are not 8-bit" if f0.dtype != np.uint8 or imgs.dtype != np.uint8 else None)
    if problem:
        raise VtsError(f"not a Taxim data pack: {problem}", npz)
    radius = radius.reshape(-1)
    (out / "presses").mkdir(parents=True, exist_ok=True)
    (out / MANIFEST_NAME).unlink(missing_ok=True)  # stale while the frames are rewritten
    write_png(out / "background.png", np.ascontiguousarray(f0, np.uint8))
    h, w = f0.shape[:2]
    entries = []
    for i, img in enumerate(imgs):
        name = f"presses/press-{i:03d}.png"
        write_png(out / name, np.ascontiguousarray(img, np.uint8))
        entries.append(Entry(f"press-{i:03d}", "press", "s0", Source(name),
                             object="calibration_ball", ball_radius_mm=float(ball_radius_mm),
                             circle=Circle(float(centre[i, 0]), float(centre[i, 1]),
                                           float(radius[i]))))
    scale = (float(mm_per_px), float(mm_per_px))
    m = Manifest(sessions=[Session("s0", sensor, (h, w), scale,
                                   background="background.png")],
                 entries=entries, name="taxim-gelsight-ball",
                 description=f"Taxim-style GelSight ball presses ({npz.name})",
                 # the name as before the move, so that a pack gives the same bytes
                 created_by="vtsbench.depth.calibration.taxim_recordings")
    save_manifest(out, m)
    return out
