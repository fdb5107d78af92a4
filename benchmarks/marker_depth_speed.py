"""Depth speed on a marker gel: frames/s of the whole image-to-depth path on 480x640 frames of
the simulated marker gel against the same gel with its dots printed with no ink, and against
the marker gel without the dots' own blur (`MarkerSpec.dot_blur_px` 0), and against the marker
gel with the harmonic fill's factorisation redone for every frame (the former code:
`markers._SYSTEMS_MAX` 0), in one alternated run (round after round, each mode once a round;
the median round).

The presses are the simulator's 3 mm ball under `zones3` light at 0.05 mm/px
(`circles_sim_variants.render_presses`), calibrated with `lut` (the fast mapping, so that the
dots' share of the time shows) on every press, then reconstructed with the DCT solver.

    .venv/bin/python benchmarks/marker_depth_speed.py [--presses 8] [--rounds 5] [--lights zones3]
"""

from __future__ import annotations

import argparse
import copy
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from circles_sim_variants import render_presses, write_folder
from machine import machine  # benchmarks/machine.py: the shared machine line

SHAPE = (480, 640)


def main() -> None:
    from vtsbench.depth import markers
    from vtsbench.depth.calibration import calibrate
    from vtsbench.depth.reconstruct import reconstruct

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--presses", type=int, default=8, help="presses to calibrate and time")
    ap.add_argument("--rounds", type=int, default=5, help="alternated timing rounds")
    ap.add_argument("--lights", default="zones3")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    cals, frames = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for gel in ("none", "markers"):
            bg, presses = render_presses(args.lights, gel, SHAPE, args.presses, args.seed)
            folder = write_folder(Path(tmp) / gel, bg, presses, gel)
            cals[gel] = calibrate(folder, method="lut", holdout=0, device=None).calibration
            frames[gel] = np.stack([p[1] for p in presses])
    spec = cals["markers"].markers
    assert spec is not None and cals["none"].markers is None
    dots = float(markers.marker_mask(cals["markers"].background, spec).mean())

    def refactorised(f: np.ndarray) -> object:
        keep, kept = markers._SYSTEMS_MAX, markers._SYSTEMS.copy()
        markers._SYSTEMS_MAX = 0  # every harmonic fill factorises its system again
        markers._SYSTEMS.clear()
        try:
            return reconstruct(f, cals["markers"])
        finally:  # the other modes find the systems they kept (the mode after this one
            markers._SYSTEMS_MAX = keep  # would otherwise factorise them again)
            markers._SYSTEMS.update(kept)

    # the same calibration without the dots' own blur (markers.DOT_BLUR_MM; its DepthMaker
    # is made anew, the background's dots are shared)
    unblurred = copy.copy(cals["markers"])
    unblurred.__dict__.pop("_maker", None)
    unblurred.markers = replace(spec, dot_blur_px=0.0)

    modes: dict[str, Callable[[], object]] = {
        "plain gel (dots with no ink)": lambda: reconstruct(frames["none"], cals["none"]),
        "marker gel": lambda: reconstruct(frames["markers"], cals["markers"]),
        f"marker gel without the dots' own blur ({spec.dot_blur_px:g} px)":
            lambda: reconstruct(frames["markers"], unblurred),
        "marker gel, factorised every frame (before)": lambda: refactorised(frames["markers"]),
    }
    for fn in modes.values():  # warm-up: lazy imports, the factorisation kept
        fn()
    times: dict[str, list[float]] = {k: [] for k in modes}
    for _ in range(args.rounds):
        for name, fn in modes.items():
            t0 = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t0)
    n = args.presses
    fps = {k: n / float(np.median(v)) for k, v in times.items()}
    print(f"Depth of {n} simulated presses at {SHAPE[0]}x{SHAPE[1]} ({args.lights}, lut + dct, "
          f"numpy path), {args.rounds} alternated rounds (median); the marker gel: "
          f"{spec.n_dots} dots of {spec.diameter_px:.1f} px, {dots:.0%} of the frame grown\n")
    print("| mode | frames/s | x marker gel |")
    print("|---|---:|---:|")
    for k, v in fps.items():
        print(f"| {k} | {v:.1f} | {v / fps['marker gel']:.2f} |")
    print(f"\nMachine: {machine()}")


if __name__ == "__main__":
    main()
