"""A real take written with each storage of `vtsbench.create`: Zarr, and video per episode
(ffv1, h264, av1); bytes on disk, window read speed and PSNR, all in one run.

Run: .venv/bin/python benchmarks/episode_video.py [--video PATH] [--fps 25] [--passes 3]

The take is the episodes benchmark's (benchmarks/episodes.py: ../shared/data/real/
incipient_slip_sample/blue_mug/exp_num_1/camera_0.avi, GelSight Mini, 320x240, 25 fps); any
video works with --video. Without the file the benchmark says so and stops (exit 0).

In a temporary folder: decodes the take once (those frames are the source), writes it as one
episode with `vtsbench.create(..., video=None | "ffv1" | "h264" | "av1")`, then per dataset:
its bytes on disk (the whole folder and data/), the seconds writing it took, windows/s of
8-frame windows at stride 8 read one a call (`windows[i]`, every window of the take; in order,
and in a random order; each pass over a freshly loaded dataset, best of --passes), and the PSNR
of every frame read back against the Zarr dataset's (mean, and the worst frame). Ratios are to
Zarr. Prints markdown tables and the machine.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from episodes import DEFAULT  # benchmarks/episodes.py: the same take
from hf import folder_bytes  # benchmarks/hf.py
from machine import machine  # benchmarks/machine.py: the shared machine line

import vtsbench
from vtsbench.recordings.media import read_frames

#: The storages compared: None is Zarr (as without video).
STORAGES = (None, "ffv1", "h264", "av1")


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    """PSNR in dB of two uint8 arrays (inf when equal)."""
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return float("inf") if mse == 0 else 10 * np.log10(255.0**2 / mse)


def write(frames: np.ndarray, out: Path, fps: float, video: str | None, obj: str) -> float:
    """The take as one episode stored with `video`; seconds it took."""
    t0 = time.perf_counter()
    with vtsbench.create(out, fps=fps, sensor="gelsight-mini", name="take", video=video) as w:
        w.add_episode(frames, object=obj, session="s0")
    return time.perf_counter() - t0


def windows_per_s(out: Path, order: str, passes: int, seed: int = 0) -> tuple[float, float]:
    """8-frame windows at stride 8 read one a call, every one in order or a random order:
    (windows/s, CPU ms a window of this process, every thread) of the fastest pass (each on
    a freshly loaded dataset: videos probed again)."""
    best = (0.0, 0.0)
    for p in range(passes):
        win = vtsbench.load(out).episodes.windows(8, 8)
        items = np.arange(len(win)) if order == "in order" else \
            np.random.default_rng(seed + p).permutation(len(win))
        t0, c0 = time.perf_counter(), time.process_time()
        for i in items:
            assert win[int(i)]["rgb"].shape[0] == 8
        rate = len(win) / (time.perf_counter() - t0)
        if rate > best[0]:
            best = (rate, (time.process_time() - c0) / len(win) * 1e3)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--video", type=Path, default=DEFAULT, help="a take (any video)")
    ap.add_argument("--fps", type=float, default=25.0, help="its frame rate")
    ap.add_argument("--passes", type=int, default=3, help="read passes (best kept)")
    args = ap.parse_args()
    if not args.video.is_file():
        print(f"skipped: {args.video} not found (the real data is absent); give a take with "
              "--video PATH")
        return
    work = Path(tempfile.mkdtemp(prefix="vtsbench-episode-video-"))
    try:
        frames = read_frames(args.video)
        obj = args.video.parent.parent.name or "object"
        rows = {}
        for video in STORAGES:
            out = work / str(video)
            secs = write(frames, out, args.fps, video, obj)
            rows[video] = {"secs": secs, "total": folder_bytes(out),
                           "data": folder_bytes(out / "data"),
                           "in order": windows_per_s(out, "in order", args.passes),
                           "random": windows_per_s(out, "random", args.passes)}
        ref = vtsbench.load(work / "None").episodes[0]["rgb"]
        assert np.array_equal(ref, frames)
        for video in STORAGES:
            got = vtsbench.load(work / str(video)).episodes[0]["rgb"]
            each = [psnr(a, b) for a, b in zip(got, ref, strict=True)]
            rows[video]["psnr"], rows[video]["worst"] = psnr(got, ref), min(each)
        n, (h, w) = len(frames), frames.shape[1:3]
        print(f"Take: {args.video.name} of {obj}/{args.video.parent.name}, {n} frames of "
              f"{w}x{h} at {args.fps:g} fps, one episode; 8-frame windows at stride 8: "
              f"{n // 8}.\n")
        z = rows[None]
        print("| storage | write s | whole folder | data/ | data/ per frame | size vs Zarr | "
              "windows/s in order (CPU ms/window) | vs Zarr | windows/s random order (CPU "
              "ms/window) | vs Zarr | PSNR dB vs Zarr (worst frame) |")
        print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
        for video, r in rows.items():
            name = "Zarr" if video is None else f"`video=\"{video}\"`"
            ps = "inf (bit-exact)" if r["psnr"] == float("inf") else \
                f"{r['psnr']:.2f} ({r['worst']:.2f})"
            print(f"| {name} | {r['secs']:.1f} | {r['total'] / 1e6:.2f} MB | "
                  f"{r['data'] / 1e6:.2f} MB | {r['data'] / n / 1e3:.1f} kB | "
                  f"{r['data'] / z['data']:.3f}x | {r['in order'][0]:.0f} "
                  f"({r['in order'][1]:.1f}) | {r['in order'][0] / z['in order'][0]:.2f}x | "
                  f"{r['random'][0]:.0f} ({r['random'][1]:.1f}) | "
                  f"{r['random'][0] / z['random'][0]:.2f}x | {ps} |")
        print(f"\nMachine: {machine()}.")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
