"""Poisson integration: frames/s per solver, dtype, batch and backend; accuracy on a 3 mm sphere.

Run: .venv/bin/python benchmarks/poisson.py [--size 480x640] [--mm-per-px 0.03] [--repeats 3]

Speed: dst, dct and masked (irregular contact masks covering ~10 % and ~40 % of the frame),
float32 and float64, batch 1 and 8, numpy (scipy.fft / scipy.sparse) and torch on the CPU (and
on CUDA when there is one); for masked also the torch conjugate-gradient path on the CPU, which
integrate_torch uses only off the CPU. Best of --repeats calls, after one warm-up call.

Accuracy: analytic 3 mm sphere pressed 0.25 / 0.5 / 1.0 mm, slopes sampled at pixel centres;
peak depth of each solver against a gs_sdk-style DCT solver (central-difference divergence
g[j+1] - g[j-1] paired with the 5-point Laplacian's eigenvalues indexed from 1), all with the
constant set as ours (border median 0). Also the forward-sampling (exact) error per solver.
Prints markdown tables and the machine.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import scipy.fft
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from machine import machine  # benchmarks/machine.py: the shared machine line

from vtsbench.depth.mask import mask_from_gradients
from vtsbench.depth.poisson import divergence, integrate, staggered

RADIUS_MM = 3.0


def contact_mask(size: tuple[int, int], share: float, seed: int = 0) -> np.ndarray:
    """An irregular contact: an ellipse-like blob with a smoothly wobbling outline, filled."""
    h, w = size
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    noise = ndimage.gaussian_filter(rng.standard_normal(size), 0.05 * h)
    noise /= noise.std()
    field = -np.hypot((x - w / 2) / 1.2, y - h / 2) + 0.05 * h * noise
    m = ndimage.binary_fill_holes(field > np.quantile(field, 1 - share))
    labels, _ = ndimage.label(m)
    return labels == 1 + int(np.argmax(np.bincount(labels.ravel())[1:]))


def bump_slopes(mask: np.ndarray, mm: float) -> tuple[np.ndarray, np.ndarray]:
    """Point slopes of a smooth bump that vanishes off the mask (content for the timings)."""
    dist = ndimage.distance_transform_edt(mask)
    z = 0.5 * (1 - np.exp(-dist / 20.0))
    return np.gradient(z, mm, axis=1), np.gradient(z, mm, axis=0)


def sphere(size: tuple[int, int], mm: float, depth: float):
    """Depth and analytic point slopes of a RADIUS_MM sphere pressed depth mm, centred."""
    h, w = size
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    x, y = (x - (w - 1) / 2 - 0.3) * mm, (y - (h - 1) / 2 + 0.2) * mm
    r2 = x * x + y * y
    inside = r2 < 2 * RADIUS_MM * depth - depth * depth
    s = np.sqrt(np.maximum(RADIUS_MM**2 - r2, 1e-12))
    return (np.where(inside, s - (RADIUS_MM - depth), 0.0), np.where(inside, -x / s, 0.0),
            np.where(inside, -y / s, 0.0))


def gs_sdk_style(p: np.ndarray, q: np.ndarray, mm: float) -> np.ndarray:
    """The mismatched DCT solver: central divergence, eigenvalues indexed from 1 (mm)."""
    h, w = p.shape
    nxt_c, prv_c = np.r_[1:w, w - 1], np.r_[0, 0:w - 1]
    nxt_r, prv_r = np.r_[1:h, h - 1], np.r_[0, 0:h - 1]
    f = (p[:, nxt_c] - p[:, prv_c]) + (q[nxt_r, :] - q[prv_r, :])
    kx, ky = np.arange(1, w + 1), np.arange(1, h + 1)
    lam = 4 * (np.sin(np.pi * kx / (2 * w))[None, :] ** 2
               + np.sin(np.pi * ky / (2 * h))[:, None] ** 2)
    z = -scipy.fft.idctn(scipy.fft.dctn(f, norm="ortho") / lam, norm="ortho") * mm
    ring = np.r_[z[0], z[-1], z[1:-1, 0], z[1:-1, -1]]
    return z - np.median(ring)


def best_time(fn: Callable[[], object], repeats: int) -> float:
    fn()
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def speed_table(size: tuple[int, int], mm: float, repeats: int) -> list[str]:
    try:
        import torch

        from vtsbench.depth.poisson_torch import integrate_torch, masked_pcg
    except ImportError:
        torch = None
    cuda = torch is not None and torch.cuda.is_available()
    masks = {"10 %": contact_mask(size, 0.10), "40 %": contact_mask(size, 0.40)}
    cases = [("dst", None), ("dct", None), ("masked", "10 %"), ("masked", "40 %")]
    head = "| solver | mask | dtype | batch | numpy | torch CPU |"
    head += " torch CUDA |" if cuda else ""
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    print("\n".join(lines), flush=True)
    for method, mname in cases:
        mask = masks[mname] if mname else masks["40 %"]
        p1, q1 = bump_slopes(mask, mm)
        for dtype in (np.float32, np.float64):
            for batch in (1, 8):
                p = np.repeat(p1[None], batch, 0).astype(dtype)
                q = np.repeat(q1[None], batch, 0).astype(dtype)
                m = np.broadcast_to(mask, p.shape) if mname else None
                kw = {"mask": m} if mname else {}
                reps = min(repeats, 2) if (mname and batch == 8) else repeats
                t = best_time(lambda p=p, q=q, kw=kw, method=method: integrate(
                    p, q, method=method, mm_per_px=mm, **kw), reps)
                row = [method, mname or "-", np.dtype(dtype).name, str(batch), f"{batch / t:.1f}"]
                if torch is None:
                    row.append("-")
                else:
                    pt, qt = torch.from_numpy(p), torch.from_numpy(q)
                    kwt = {"mask": torch.from_numpy(np.array(m))} if mname else {}
                    if mname:
                        # integrate_torch hands CPU frames to the numpy solver; time the CG
                        # path that it uses on GPUs, on the CPU, for the comparison.
                        b = torch.from_numpy(divergence(*staggered(p, q, "point"), mm, mm,
                                                        "dirichlet"))
                        t = best_time(lambda b=b, kwt=kwt: masked_pcg(b, kwt["mask"], mm, mm),
                                      reps)
                        row.append(f"{batch / t:.1f} (CG)")
                    else:
                        t = best_time(lambda pt=pt, qt=qt, method=method: integrate_torch(
                            pt, qt, method=method, mm_per_px=mm), repeats)
                        row.append(f"{batch / t:.1f}")
                if cuda:
                    pc, qc = pt.cuda(), qt.cuda()
                    kwc = {"mask": kwt["mask"].cuda()} if mname else {}

                    def run(pc=pc, qc=qc, kwc=kwc, method=method) -> None:
                        integrate_torch(pc, qc, method=method, mm_per_px=mm, **kwc)
                        torch.cuda.synchronize()

                    t = best_time(run, max(repeats, 5))
                    row.append(f"{batch / t:.1f}")
                lines.append("| " + " | ".join(row) + " |")
                print(lines[-1], flush=True)
    return lines


def accuracy_tables(size: tuple[int, int], mm: float) -> list[str]:
    lines = [f"Peak depth of a {RADIUS_MM:g} mm sphere, {size[0]}x{size[1]} at {mm} mm/px, "
             "analytic slopes at pixel centres (error in % of the press depth):", "",
             "| press depth | gs_sdk-style DCT | ours dct | ours dst | ours masked (estimated "
             "mask) | gs_sdk-style / ours dct |", "|---|---|---|---|---|---|"]
    for depth in (0.25, 0.5, 1.0):
        z, p, q = sphere(size, mm, depth)
        gs = gs_sdk_style(p, q, mm)
        ours = {m: integrate(p, q, method=m, mm_per_px=mm) for m in ("dct", "dst")}
        ours["masked"] = integrate(p, q, method="masked", mm_per_px=mm,
                                   mask=mask_from_gradients(p, q))
        err = {k: 100 * (v.max() - depth) / depth for k, v in ours.items()}
        e_gs = 100 * (gs.max() - depth) / depth
        lines.append(f"| {depth:g} mm | {gs.max():.4f} mm ({e_gs:+.1f} %) | "
                     + " | ".join(f"{ours[k].max():.4f} mm ({err[k]:+.3f} %)"
                                  for k in ("dct", "dst", "masked"))
                     + f" | {abs(e_gs / err['dct']):.0f}x |")
    z, _, _ = sphere(size, mm, 0.5)
    zp = np.pad(z, ((0, 1), (0, 1)))
    p, q = (zp[:-1, 1:] - zp[:-1, :-1]) / mm, (zp[1:, :-1] - zp[:-1, :-1]) / mm
    lines += ["", "Forward sampling (the solvers' own discretisation), same sphere 0.5 mm deep, "
              "max |error| over the frame:", "", "| solver | float64 | float32 |", "|---|---|---|"]
    for method in ("dst", "dct", "masked"):
        kw = {"mask": z > 0} if method == "masked" else {}
        e = [np.abs(integrate(p.astype(dt), q.astype(dt), method=method, mm_per_px=mm,
                              sampling="forward", **kw) - z).max() for dt in (np.float64,
                                                                             np.float32)]
        lines.append(f"| {method} | {e[0]:.1e} mm | {e[1]:.1e} mm |")
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="480x640")
    ap.add_argument("--mm-per-px", type=float, default=0.03)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--skip-speed", action="store_true")
    args = ap.parse_args()
    size = tuple(int(v) for v in args.size.lower().split("x"))
    print(f"Machine: {machine()}\n")
    if not args.skip_speed:
        print(f"Frames/s at {size[0]}x{size[1]}, point sampling, best of {args.repeats}:\n")
        speed_table(size, args.mm_per_px, args.repeats)
        print()
    print("\n".join(accuracy_tables(size, args.mm_per_px)))


if __name__ == "__main__":
    main()
