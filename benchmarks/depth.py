"""Depth: every mapping x solver at 480x640 — frames/s and held-out error, simulated and real.

For each mapping (lut, poly, mlp) a calibration is fitted on simulated sphere presses with exact
ground truth (a seed the tests never use) and, when ../shared/data/real is present, on the real
GelSight presses of Taxim (leave presses out). Each held-out press is reconstructed with each
solver (dst, dct, masked) and scored with the plane-aligned RMSE over the true contact region
(mm); speed is frames/s of the whole image-to-depth path on 480x640 frames (numpy path, 2 cores).

    .venv/bin/python benchmarks/depth.py [--presses 30] [--holdout 6] [--frames 16]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from machine import machine  # benchmarks/machine.py: the shared machine line

from vtsbench.depth.calibration import calibrate, evaluate_press, load_presses, taxim_recordings
from vtsbench.depth.reconstruct import reconstruct

METHODS = ("lut", "poly", "mlp")
SOLVERS = ("dst", "dct", "masked")
TAXIM = (Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "taxim_gelsight_ball"
         / "dataPack_small.npz")


def fps(cal, frames: np.ndarray, solver: str, device: str | None, repeats: int = 2) -> float:
    """Best-of-repeats frames/s of image -> depth over a batch of frames."""
    reconstruct(frames[:1], cal, solver=solver, device=device)  # warm-up
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        reconstruct(frames, cal, solver=solver, device=device)
        best = min(best, time.perf_counter() - t0)
    return len(frames) / best


def held_out_rmse(run, solver: str) -> float:
    """Mean plane-aligned RMSE (mm) over the held-out presses with this solver."""
    errs = [evaluate_press(run.calibration, h.press, solver=solver).errors for h in run.held_out]
    return float(np.mean([e["plane_aligned_rmse_mm"] for e in errs]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--presses", type=int, default=30)
    ap.add_argument("--holdout", type=int, default=6)
    ap.add_argument("--frames", type=int, default=16, help="frames per speed measurement")
    ap.add_argument("--seed", type=int, default=9090, help="simulation seed (unused by tests)")
    args = ap.parse_args()
    from vtsbench.sim.simulate import simulate

    rows: list[tuple] = []
    real: dict[tuple[str, str], float] = {}
    with tempfile.TemporaryDirectory() as tmp:
        sim = Path(tmp) / "sim"
        simulate(sim, seed=args.seed, n_static=0, n_sequences=0, n_presses=args.presses,
                 workers=2, progress=False)
        presses, *_ = load_presses(sim)
        frames = np.stack([presses[i % len(presses)].image for i in range(args.frames)])
        taxim = taxim_recordings(TAXIM, Path(tmp) / "taxim") if TAXIM.is_file() else None
        for method in METHODS:
            run = calibrate(sim, method=method, holdout=args.holdout, seed=0, device=None)
            for solver in SOLVERS:
                rmse = held_out_rmse(run, solver)
                speed = fps(run.calibration, frames, solver, None)
                rows.append((method, solver, speed, rmse, run.seconds))
                print(f"{method:5s} {solver:7s} {speed:7.1f} frames/s  {rmse:.4f} mm",
                      file=sys.stderr)
            if taxim is not None:
                truns = [calibrate(taxim, method=method, holdout=9, seed=s, device=None)
                         for s in range(3)]
                for solver in SOLVERS:
                    real[(method, solver)] = float(np.mean([held_out_rmse(r, solver)
                                                            for r in truns]))
    print(f"Depth at 480x640: {args.presses} simulated presses (seed {args.seed}), "
          f"{args.holdout} held out; speed over {args.frames} frames, numpy path, best of 2\n")
    print("| mapping | solver | frames/s | held-out plane-aligned RMSE, simulated (mm) | "
          "leave-presses-out RMSE, Taxim GelSight (mm) |")
    print("|---|---|---:|---:|---:|")
    for method, solver, speed, rmse, _ in rows:
        r = real.get((method, solver))
        print(f"| {method} | {solver} | {speed:.1f} | {rmse:.4f} | "
              f"{'n/a' if r is None else f'{r:.3f}'} |")
    print(f"\nMachine: {machine()}")


if __name__ == "__main__":
    main()
