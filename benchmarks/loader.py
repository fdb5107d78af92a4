"""Loader throughput: slip sequences/s through vtsbench.load against a PNG folder and datasets.

Run: .venv/bin/python benchmarks/loader.py [--sequences 24] [--size 480x640] [--repeats 3]
     [--dataset BUILT_DATASET]

Builds a dataset from simulated recordings (simulate, calibrate, build) in a temporary folder,
then writes the same slip samples two other ways: (a) a folder of PNGs, one per frame, depth as
16-bit PNG (the int16 counts' bits), and (b) a `datasets` parquet file with `Image()` features
(the same PNG bytes). Every reader returns rgb uint8 (T, H, W, 3) and depth float32 mm (T, H, W)
per sequence. Reported: sequences/s in index order and in a random order (best of --repeats,
page cache warm: this measures decoding, not the disk), and DataLoader throughput with 0 and 2
workers. Prints a markdown table and the machine; removes everything it wrote.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from machine import machine  # benchmarks/machine.py: the shared machine line

import vtsbench
from vtsbench.dataset.format.arrays import depth_to_int16
from vtsbench.dataset.format.layout import DEPTH_SCALE_MM
from vtsbench.dataset.read.view import View

Reader = Callable[[int], tuple[np.ndarray, np.ndarray]]


def build_dataset(work: Path, sequences: int, size: tuple[int, int]) -> Path:
    """Simulated recordings -> calibration (poly) -> dataset, with the library functions."""
    from vtsbench.dataset.build.pipeline import BuildOptions, build
    from vtsbench.depth.calibration import calibrate, save_calibration
    from vtsbench.sim.simulate import simulate

    rec = work / "recordings"
    simulate(rec, seed=0, n_static=2, n_sequences=sequences, n_presses=12, size=size,
             mm_per_px=0.03, workers=2, progress=False)
    run = calibrate(rec, method="poly")
    save_calibration(run.calibration, rec / "calibration.safetensors")
    build(rec, work / "dataset", BuildOptions(workers=2))
    return work / "dataset"


# -- the two other formats ------------------------------------------------------------------


def write_png_folder(view: View, root: Path) -> None:
    """One folder per sequence: rgb_000.png ... and depth_000.png (16-bit, int16 bits)."""
    import cv2

    for i, sid in enumerate(view.ids):
        d = root / sid
        d.mkdir(parents=True)
        a = view.read([i], ("rgb", "depth"))
        counts = depth_to_int16(a["depth"][0])
        for t, (rgb, dep) in enumerate(zip(a["rgb"][0], counts, strict=True)):
            cv2.imwrite(str(d / f"rgb_{t:03d}.png"), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
            cv2.imwrite(str(d / f"depth_{t:03d}.png"), dep.view(np.uint16))


def png_reader(root: Path, ids: Sequence[str], frames: int) -> Reader:
    """Read sequence i of the PNG folder as (rgb, depth mm)."""
    import cv2

    def read(i: int) -> tuple[np.ndarray, np.ndarray]:
        d = root / ids[i]
        rgb = np.stack([cv2.cvtColor(cv2.imread(str(d / f"rgb_{t:03d}.png"), cv2.IMREAD_COLOR),
                                     cv2.COLOR_BGR2RGB) for t in range(frames)])
        dep = np.stack([cv2.imread(str(d / f"depth_{t:03d}.png"), cv2.IMREAD_UNCHANGED)
                        for t in range(frames)])
        return rgb, dep.view(np.int16).astype(np.float32) * np.float32(DEPTH_SCALE_MM)

    return read


def write_hf_parquet(png_root: Path, ids: Sequence[str], frames: int, path: Path) -> None:
    """A datasets parquet file: sample_id, rgb and depth as sequences of Image() (PNG bytes)."""
    import datasets

    datasets.disable_progress_bars()
    feats = datasets.Features({"sample_id": datasets.Value("string"),
                               "rgb": datasets.Sequence(datasets.Image()),
                               "depth": datasets.Sequence(datasets.Image())})

    def rows() -> Any:
        for sid in ids:
            d = png_root / sid
            yield {"sample_id": sid,
                   "rgb": [{"bytes": (d / f"rgb_{t:03d}.png").read_bytes(), "path": None}
                           for t in range(frames)],
                   "depth": [{"bytes": (d / f"depth_{t:03d}.png").read_bytes(), "path": None}
                             for t in range(frames)]}

    ds = datasets.Dataset.from_generator(rows, features=feats, writer_batch_size=4,
                                         cache_dir=str(path.parent / "hf-cache-write"))
    ds.to_parquet(str(path))


def hf_reader(path: Path, cache: Path) -> Reader:
    """Read row i of the parquet file through datasets (Image() decoding) as (rgb, depth mm)."""
    import datasets

    datasets.disable_progress_bars()
    ds = datasets.Dataset.from_parquet(str(path), cache_dir=str(cache)).with_format("numpy")

    def read(i: int) -> tuple[np.ndarray, np.ndarray]:
        row = ds[i]
        rgb = np.stack(row["rgb"]).astype(np.uint8, copy=False)
        dep = np.stack(row["depth"]).astype(np.uint16, copy=False).view(np.int16)
        return rgb, dep.astype(np.float32) * np.float32(DEPTH_SCALE_MM)

    return read


def ours_reader(view: View) -> Reader:
    """Read sequence i through the loader (rgb and depth only)."""

    def read(i: int) -> tuple[np.ndarray, np.ndarray]:
        a = view.read([i], ("rgb", "depth"))
        return a["rgb"][0], a["depth"][0]

    return read


# -- timing -------------------------------------------------------------------------------


def pass_seconds(read: Reader, order: Sequence[int]) -> float:
    """Seconds to read every index in order."""
    t0 = time.perf_counter()
    for i in order:
        read(i)
    return time.perf_counter() - t0


def loader_seconds(dataset: Any, workers: int, seed: int, batch: int = 4) -> float:
    """Seconds of one shuffled DataLoader pass (batch of 4) over a torch dataset."""
    import torch
    from torch.utils.data import DataLoader

    dl = DataLoader(dataset, batch_size=batch, shuffle=True,
                    generator=torch.Generator().manual_seed(seed), num_workers=workers)
    t0 = time.perf_counter()
    for _ in dl:
        pass
    return time.perf_counter() - t0


def best_rates(jobs: dict[Any, Callable[[int], float]], n: int, repeats: int) -> dict[Any, float]:
    """Items/s of every job, best of repeats; the jobs take turns within each repeat so that
    load from other processes falls on all of them alike."""
    best = dict.fromkeys(jobs, float("inf"))
    for r in range(repeats):
        for key, job in jobs.items():
            best[key] = min(best[key], job(r))
    return {k: n / v for k, v in best.items()}


class PngTorch:
    """The PNG folder as a torch dataset of (rgbd tensor T x 4 x H x W, index)."""

    def __init__(self, read: Reader, n: int) -> None:
        self.read, self.n = read, n

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, i: int) -> tuple[Any, int]:
        import torch

        rgb, dep = self.read(i)
        x = torch.from_numpy(rgb).movedim(-1, -3).to(torch.float32).div_(255.0)
        return torch.cat([x, torch.from_numpy(dep).unsqueeze(-3)], dim=-3), i


def check_same(readers: dict[str, Reader], n: int) -> None:
    """Every reader returns the same arrays for every sequence."""
    for i in range(n):
        ref_rgb, ref_dep = readers["ours"](i)
        for name, read in readers.items():
            rgb, dep = read(i)
            if not (np.array_equal(rgb, ref_rgb) and np.array_equal(dep, ref_dep)):
                raise SystemExit(f"{name} differs from the loader at sequence {i}")


def run(work: Path, sequences: int, size: tuple[int, int], repeats: int,
        dataset: Path | None = None) -> str:
    """Build (unless given a dataset), write the other formats, time every reader; returns the
    markdown report."""
    t0 = time.perf_counter()
    ds_path = dataset or build_dataset(work, sequences, size)
    t_build = time.perf_counter() - t0
    view = vtsbench.load(ds_path).slip
    n, frames = len(view), view.dataset.info.frames_per_sequence
    png_root = work / "png"
    write_png_folder(view, png_root)
    write_hf_parquet(png_root, view.ids, frames, work / "slip.parquet")
    readers = {"ours": ours_reader(view), "png": png_reader(png_root, view.ids, frames),
               "hf": hf_reader(work / "slip.parquet", work / "hf-cache-read")}
    check_same(readers, n)
    seq = list(range(n))
    rnd = [int(i) for i in np.random.default_rng(0).permutation(n)]
    jobs: dict[Any, Callable[[int], float]] = {}
    for k, r in readers.items():
        jobs[(k, "sequential")] = partial(lambda r, _: pass_seconds(r, seq), r)
        jobs[(k, "random")] = partial(lambda r, _: pass_seconds(r, rnd), r)
    rates = best_rates(jobs, n, repeats)
    torch_sets = {"ours": view.to_torch("rgbd"),
                  "ours-small": view.to_torch("rgbd", size=(240, 320), frames=4),
                  "png": PngTorch(readers["png"], n)}
    dl = best_rates({(k, w): partial(loader_seconds, d, w) for k, d in torch_sets.items()
                     for w in (0, 2)}, n, repeats)

    sizes = {
        "ours": du(ds_path / "data" / "slip.zarr"),
        "png": du(png_root),
        "hf": (work / "slip.parquet").stat().st_size,
    }
    h, w = view.dataset.info.resolution
    names = {"ours": "vtsbench loader (Zarr, zstd)", "png": "PNG folder (OpenCV)",
             "hf": "datasets parquet, Image() (PIL)"}
    lines = [
        f"{n} slip sequences of {frames} x {h} x {w} x 3 RGB + depth; best of {repeats}"
        + ("." if dataset else f"; dataset build {t_build:.0f} s."),
        "",
        "| reader | on disk (MB) | sequential (seq/s) | random order (seq/s) | "
        "ours / this (sequential) |",
        "|---|---:|---:|---:|---:|",
    ]
    for k in ("ours", "png", "hf"):
        ratio = rates[("ours", "sequential")] / rates[(k, "sequential")]
        lines.append(f"| {names[k]} | {sizes[k] / 1e6:.0f} | {rates[(k, 'sequential')]:.1f} | "
                     f"{rates[(k, 'random')]:.1f} | {ratio:.1f}x |")
    lines += ["", "| DataLoader, shuffled, batch 4 | tensors per sequence | 0 workers (seq/s) | "
              "2 workers (seq/s) |", "|---|---|---:|---:|"]
    shapes = {"ours": f"{frames} x 4 x {h} x {w}", "ours-small": "4 x 4 x 240 x 320",
              "png": f"{frames} x 4 x {h} x {w}"}
    labels = {"ours": names["ours"] + ', `to_torch("rgbd")`',
              "ours-small": names["ours"] + ', `to_torch("rgbd", size=(240, 320), frames=4)`',
              "png": names["png"] + ", same tensors as the first row"}
    for k in ("ours", "ours-small", "png"):
        lines.append(f"| {labels[k]} | {shapes[k]} | {dl[(k, 0)]:.1f} | {dl[(k, 2)]:.1f} |")
    lines += ["", f"Machine: {machine()}."]
    return "\n".join(lines)


def du(path: Path) -> int:
    """Bytes of the files under path."""
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sequences", type=int, default=24)
    ap.add_argument("--size", default="480x640")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--workdir", type=Path, default=None,
                    help="Folder for the files (default: a temporary one, removed at the end).")
    ap.add_argument("--dataset", type=Path, default=None,
                    help="Use this built dataset's slip samples instead of building one.")
    args = ap.parse_args()
    size = tuple(int(v) for v in args.size.lower().split("x"))
    work = Path(tempfile.mkdtemp(prefix="vtsbench-loader-", dir=args.workdir))
    try:
        print(run(work, args.sequences, (size[0], size[1]), args.repeats, args.dataset))
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
