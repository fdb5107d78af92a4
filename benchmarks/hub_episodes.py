"""The episodes' Hugging Face copy (hf/episodes/) of a real take: export time and bytes against
its Zarr store, and load_dataset's read rate against ds.episodes, in one run.

Run: .venv/bin/python benchmarks/hub_episodes.py [--video PATH] [--fps 25] [--repeats 3]

The default take is benchmarks/episodes.py's (../shared/data/real/incipient_slip_sample/
blue_mug/exp_num_1/camera_0.avi: GelSight Mini, 228 frames of 320x240 at 25 fps); without the
file the benchmark says so and stops (exit 0).

In a temporary folder:
1. writes the take as one episode with `vtsbench.create` (rgb, zstd level 3);
2. `vtsbench export-hf` of it with 2 threads, timed (in process, after a warm-up import);
3. the bytes of data/episodes.zarr and of hf/episodes/ (its parquet files and meta files);
4. reads every frame's rgb, timestamp and labels, taking turns within each of `--repeats`
   repeats (best counts, page cache warm): `ds.episodes[i]` (the Zarr store), and
   `datasets.load_dataset(OUT, "episodes")` with `.with_format("numpy")` (after its one-off
   Arrow cache, timed apart), and the same with `streaming=True`; every read is checked
   against the store bit for bit once;
5. prints a markdown table and the machine.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import numpy as np
from episodes import DEFAULT  # benchmarks/episodes.py: the same take
from hf import folder_bytes  # benchmarks/hf.py
from machine import machine  # benchmarks/machine.py: the shared machine line

import vtsbench
from vtsbench.recordings.media import read_frames


def zarr_read(out: Path) -> tuple[np.ndarray, np.ndarray]:
    """Every frame's rgb and timestamp through ds.episodes (a fresh load)."""
    eps = vtsbench.load(out).episodes
    rgb, ts = [], []
    for i in range(len(eps)):
        ep = eps.episode(i, ("rgb",))
        rgb.append(ep["rgb"])
        ts.append(ep["timestamps"])
    return np.concatenate(rgb), np.concatenate(ts)


def hub_read(d: Any) -> tuple[np.ndarray, np.ndarray]:
    """Every frame's rgb and timestamp of the copy, rows in the numpy format."""
    rgb, ts = [], []
    for row in d.with_format("numpy"):
        rgb.append(row["observation.images.rgb"])
        ts.append(row["timestamp"])
    return np.stack(rgb), np.asarray(ts)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--video", type=Path, default=DEFAULT, help="a take (any video)")
    ap.add_argument("--fps", type=float, default=25.0)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    if not args.video.is_file():
        print(f"skipped: {args.video} not found (the real data is absent); give a take with "
              "--video PATH")
        return
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    import datasets

    from vtsbench.dataset.tools.hub import export_hf

    work = Path(tempfile.mkdtemp(prefix="vts-hub-episodes-"))
    try:
        out = work / "take"
        frames = read_frames(args.video)
        with vtsbench.create(out, fps=args.fps, sensor="gelsight-mini", name="take") as w:
            w.add_episode(frames, object=args.video.parent.parent.name or "object",
                          session="s0", source=args.video.name)
        t0 = time.perf_counter()
        export_hf(out, workers=2)
        export_s = time.perf_counter() - t0
        zarr_b = folder_bytes(out / "data" / "episodes.zarr")
        hub = out / "hf" / "episodes"
        parquet_b = folder_bytes(hub / "data")
        meta_b = folder_bytes(hub / "meta")
        cache = work / "cache"
        t0 = time.perf_counter()
        full = datasets.load_dataset(str(out), "episodes", split="full", cache_dir=str(cache))
        cache_s = time.perf_counter() - t0
        cache_b = folder_bytes(cache)
        stream = datasets.load_dataset(str(out), "episodes", split="full", streaming=True)
        readers = {"`ds.episodes[i]` (Zarr)": lambda: zarr_read(out),
                   "`load_dataset(OUT, \"episodes\")`, Arrow cache, numpy format":
                       lambda: hub_read(full),
                   "`load_dataset(..., streaming=True)`, numpy format": lambda: hub_read(stream)}
        want = zarr_read(out)
        best = dict.fromkeys(readers, float("inf"))
        for r in range(args.repeats):
            for name, read in readers.items():
                t0 = time.perf_counter()
                got = read()
                best[name] = min(best[name], time.perf_counter() - t0)
                if r == 0:
                    assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
        n = len(frames)
        h, w_ = frames.shape[1:3]
        print(f"Take: {args.video.parent.parent.name}/{args.video.parent.name}/"
              f"{args.video.name}, {n} frames of {w_}x{h} at {args.fps:g} fps, one episode.\n")
        print("| what | value |\n|---|---:|")
        print(f"| `vtsbench export-hf` (2 threads), s | {export_s:.2f} |")
        print(f"| `data/episodes.zarr`, MB | {zarr_b / 1e6:.2f} |")
        print(f"| `hf/episodes/data/` (parquet), MB | {parquet_b / 1e6:.2f} "
              f"({parquet_b / zarr_b:.2f}x the Zarr store) |")
        print(f"| `hf/episodes/meta/`, KB | {meta_b / 1e3:.1f} |")
        print(f"| `load_dataset`'s first call (Arrow cache {cache_b / 1e6:.2f} MB), s | "
              f"{cache_s:.2f} |")
        base = n / best["`ds.episodes[i]` (Zarr)"]
        print("\n| reader, every frame (rgb, timestamp) | frames/s | / Zarr |\n|---|---:|---:|")
        for name, secs in best.items():
            print(f"| {name} | {n / secs:.0f} | {n / secs / base:.2f} |")
        print(f"\nMachine: {machine()}")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
