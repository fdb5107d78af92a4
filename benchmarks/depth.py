"""Depth: every mapping x solver at 480x640 — frames/s and held-out error, simulated and real.

For each mapping (lut, poly, mlp) a calibration is fitted on simulated sphere presses with exact
ground truth (a seed the tests never use) and, when ../shared/data/real is present, on the real
GelSight presses of Taxim (leave presses out). Each held-out press is reconstructed with each
solver (dst, dct, masked) and scored with the plane-aligned RMSE over the true contact region
(mm). Speed: frames/s of the whole image-to-depth path on 480x640 frames (numpy path), every
mode and a gs_sdk-style reference (benchmarks/gs_sdk_style.py: its MLP, DCT solve and contact
mask) timed in one alternated run (round after round, each mode once per round; the median
round), with each mode's ratio to the reference of the same run.

    .venv/bin/python benchmarks/depth.py [--presses 30] [--holdout 6] [--frames 8] [--rounds 5]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from gs_sdk_style import GsSdkStyle  # benchmarks/gs_sdk_style.py: the reference pipeline
from machine import machine  # benchmarks/machine.py: the shared machine line

from vtsbench.depth.calibration import calibrate, evaluate_press, load_presses, taxim_recordings
from vtsbench.depth.reconstruct import reconstruct

METHODS = ("lut", "poly", "mlp")
SOLVERS = ("dst", "dct", "masked")
TAXIM = (Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "taxim_gelsight_ball"
         / "dataPack_small.npz")


def alternated(modes: dict[str, Callable[[np.ndarray], object]], frames: np.ndarray,
               rounds: int) -> dict[str, float]:
    """Median frames/s of each mode over `rounds` rounds, each round timing every mode once on
    the same frames (so that a load change on a shared machine hits every mode alike)."""
    for fn in modes.values():  # warm-up: caches, lazy imports
        fn(frames[:1])
    times: dict[str, list[float]] = {k: [] for k in modes}
    for _ in range(rounds):
        for name, fn in modes.items():
            t0 = time.perf_counter()
            fn(frames)
            times[name].append(time.perf_counter() - t0)
    return {k: len(frames) / float(np.median(v)) for k, v in times.items()}


def held_out_rmse(run, solver: str) -> float:
    """Mean plane-aligned RMSE (mm) over the held-out presses with this solver."""
    errs = [evaluate_press(run.calibration, h.press, solver=solver).errors for h in run.held_out]
    return float(np.mean([e["plane_aligned_rmse_mm"] for e in errs]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--presses", type=int, default=30)
    ap.add_argument("--holdout", type=int, default=6)
    ap.add_argument("--frames", type=int, default=8, help="frames per mode and round")
    ap.add_argument("--rounds", type=int, default=5, help="alternated timing rounds")
    ap.add_argument("--seed", type=int, default=9090, help="simulation seed (unused by tests)")
    ap.add_argument("--no-real", action="store_true", help="skip the Taxim GelSight fits")
    ap.add_argument("--threads", type=int, default=2,
                    help="torch threads of the reference (and of the mlp mapping)")
    args = ap.parse_args()
    from vtsbench.sim.simulate import simulate

    sim_rmse: dict[tuple[str, str], float] = {}
    real: dict[tuple[str, str], float] = {}
    cals = {}
    with tempfile.TemporaryDirectory() as tmp:
        sim = Path(tmp) / "sim"
        simulate(sim, seed=args.seed, n_static=0, n_sequences=0, n_presses=args.presses,
                 workers=2, progress=False)
        presses, *_ = load_presses(sim)
        frames = np.stack([presses[i % len(presses)].image for i in range(args.frames)])
        taxim = taxim_recordings(TAXIM, Path(tmp) / "taxim") \
            if TAXIM.is_file() and not args.no_real else None
        for method in METHODS:
            run = calibrate(sim, method=method, holdout=args.holdout, seed=0, device=None)
            cals[method] = run.calibration
            for solver in SOLVERS:
                sim_rmse[(method, solver)] = held_out_rmse(run, solver)
                print(f"{method:5s} {solver:7s} {sim_rmse[(method, solver)]:.4f} mm",
                      file=sys.stderr)
            if taxim is not None:
                truns = [calibrate(taxim, method=method, holdout=9, seed=s, device=None)
                         for s in range(3)]
                for solver in SOLVERS:
                    real[(method, solver)] = float(np.mean([held_out_rmse(r, solver)
                                                            for r in truns]))
        ref = GsSdkStyle(cals["lut"].background, cals["lut"].mm_per_px[0], args.threads)
        modes: dict[str, Callable[[np.ndarray], object]] = {
            "gs_sdk-style": lambda f: [ref.surface(x) for x in f]}
        for method in METHODS:
            for solver in SOLVERS:
                modes[f"{method} {solver}"] = (
                    lambda f, c=cals[method], s=solver: reconstruct(f, c, solver=s))
        speed = alternated(modes, frames, args.rounds)
    base = speed["gs_sdk-style"]
    print(f"Depth at 480x640: {args.presses} simulated presses (seed {args.seed}), "
          f"{args.holdout} held out; speed: {args.frames} frames per mode, {args.rounds} "
          "alternated rounds (median), numpy path\n")
    print("| mapping | solver | frames/s | x gs_sdk-style | held-out plane-aligned RMSE, "
          "simulated (mm) | leave-presses-out RMSE, Taxim GelSight (mm) |")
    print("|---|---|---:|---:|---:|---:|")
    print(f"| gs_sdk-style (5-32-32-32-2 MLP, torch, {args.threads} threads) | its DCT + "
          "contact mask | "
          f"{base:.1f} | 1.0 | - | - |")
    for method in METHODS:
        for solver in SOLVERS:
            k = f"{method} {solver}"
            r = real.get((method, solver))
            print(f"| {method} | {solver} | {speed[k]:.1f} | {speed[k] / base:.1f} | "
                  f"{sim_rmse[(method, solver)]:.4f} | {'n/a' if r is None else f'{r:.3f}'} |")
    print(f"\nMachine: {machine()}")


if __name__ == "__main__":
    main()
