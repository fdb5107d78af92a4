"""The Hugging Face copy (`vtsbench export-hf`): its cost, size on disk and read speed against
the Zarr store, in one run.

Run: .venv/bin/python benchmarks/hf.py [--sequences 24] [--static 24] [--size 480x640]
     [--workers 2] [--repeats 3]

Simulates recordings, calibrates and builds a dataset (`--workers` processes), then exports its
Hugging Face copy (`--workers` threads) and reports: build and export seconds (and their ratio),
bytes on disk of the Zarr arrays, the parquet copy and its columns, and slip samples/s read
(rgb uint8, depth float32 mm, contact bool per sample, page cache warm: decoding, not the disk)
by (a) `vtsbench.load` iterating a view, (b) `datasets.load_dataset(..., "slip_all")` with
`.with_format("numpy")` after its one-off conversion to the Arrow cache (timed apart), (c) the
same with `streaming=True` (numpy format too), (d) `view.to_hf()` streamed from the Zarr store.
Readers alternate within each repeat; best of --repeats. Prints markdown tables and the
machine; removes everything it wrote.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from machine import machine  # benchmarks/machine.py: the shared machine line

import vtsbench


def make_dataset(work: Path, sequences: int, static: int, size: tuple[int, int],
                 workers: int) -> tuple[Path, float]:
    """Simulated recordings -> calibration (lut) -> dataset; returns it and the build seconds."""
    from vtsbench.dataset.build.pipeline import BuildOptions, build
    from vtsbench.depth.calibration import calibrate, save_calibration
    from vtsbench.sim.simulate import simulate

    rec = work / "recordings"
    simulate(rec, seed=0, n_static=static, n_sequences=sequences, n_presses=12, size=size,
             mm_per_px=0.03, workers=workers, progress=False)
    run = calibrate(rec, method="lut")
    save_calibration(run.calibration, rec / "calibration.safetensors")
    t0 = time.perf_counter()
    build(rec, work / "dataset", BuildOptions(workers=workers))
    return work / "dataset", time.perf_counter() - t0


def folder_bytes(root: Path) -> int:
    return sum(p.stat().st_size for p in root.rglob("*") if p.is_file())


def column_bytes(folder: Path) -> dict[str, int]:
    """Compressed bytes per top-level column over the parquet files of a folder."""
    import pyarrow.parquet as pq

    out: dict[str, int] = {}
    for p in folder.rglob("*.parquet"):
        meta = pq.ParquetFile(p).metadata
        for g in range(meta.num_row_groups):
            rg = meta.row_group(g)
            for c in range(rg.num_columns):
                col = rg.column(c)
                name = col.path_in_schema.split(".")[0]
                out[name] = out.get(name, 0) + col.total_compressed_size
    return out


def consume(rows: Iterable[dict[str, Any]]) -> int:
    """Touch every sample's arrays as numpy (rgb uint8, depth float32, contact bool)."""
    n = 0
    for r in rows:
        rgb = np.asarray(r["rgb"])
        depth = np.asarray(r["depth"])
        contact = np.asarray(r["contact"])
        assert rgb.dtype == np.uint8 and depth.dtype == np.float32 and contact.dtype == bool
        n += 1
    return n


def numpy_rows(ds: Any, scale_mm: float = 0.001) -> Iterable[dict[str, Any]]:
    """Rows of a datasets Dataset or IterableDataset as numpy, images as uint8 arrays, depth in
    mm: from the 16-bit images of the int16 counts (hub layout 2) or as stored (layout 1)."""
    for r in ds:
        r = dict(r)
        for name in ("rgb", "depth", "contact"):
            if isinstance(r[name], list):
                r[name] = np.stack([np.asarray(im) for im in r[name]])
        depth = np.asarray(r["depth"])
        r["depth"] = (depth.view(np.int16).astype(np.float32) * np.float32(scale_mm)
                      if depth.dtype == np.uint16 else depth.astype(np.float32))
        r["contact"] = np.asarray(r["contact"], dtype=bool)
        yield r


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sequences", type=int, default=24)
    ap.add_argument("--static", type=int, default=24)
    ap.add_argument("--size", default="480x640")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args()
    size = tuple(int(v) for v in a.size.split("x"))
    work = Path(tempfile.mkdtemp(prefix="vtsbench-hf-"))
    try:
        run(work, a, size)  # type: ignore[arg-type]
    finally:
        shutil.rmtree(work, ignore_errors=True)


def run(work: Path, a: argparse.Namespace, size: tuple[int, int]) -> None:
    import datasets

    from vtsbench.dataset.format.layout import HUB_DIR
    from vtsbench.dataset.tools.hub import export_hf

    datasets.disable_progress_bars()
    root, build_s = make_dataset(work, a.sequences, a.static, size, a.workers)
    t0 = time.perf_counter()
    export_hf(root, workers=a.workers)
    export_s = time.perf_counter() - t0
    ds = vtsbench.load(root)
    frames = len(ds.static) + len(ds.slip) * ds.info.frames_per_sequence
    zarr_b, hub_b = folder_bytes(root / "data"), folder_bytes(root / HUB_DIR)
    raw = frames * size[0] * size[1] * (3 + 4 + 1)  # uint8 rgb, float32 depth, bool contact

    cache = work / "cache"
    t0 = time.perf_counter()
    arrow = datasets.load_dataset(str(root), "slip_all", split="full", cache_dir=str(cache))
    prepare_s = time.perf_counter() - t0
    arrow_np = arrow.with_format("numpy")
    view = ds.slip
    readers: dict[str, Callable[[], int]] = {
        "vtsbench.load (Zarr), iterating a view": lambda: consume(view),
        "load_dataset, Arrow cache, numpy format": lambda: consume(numpy_rows(arrow_np)),
        "load_dataset(streaming=True), parquet, numpy format": lambda: consume(numpy_rows(
            datasets.load_dataset(str(root), "slip_all", split="full", streaming=True)
            .with_format("numpy"))),
        "view.to_hf(), streamed from Zarr": lambda: consume(view.to_hf()),
    }
    best = {k: float("inf") for k in readers}
    for _ in range(a.repeats):
        for name, read in readers.items():
            t0 = time.perf_counter()
            n = read()
            best[name] = min(best[name], time.perf_counter() - t0)
            assert n == len(view)
    base = len(view) / best["vtsbench.load (Zarr), iterating a view"]

    print(f"\n{len(ds.static)} static + {len(ds.slip)} slip samples of "
          f"{ds.info.frames_per_sequence} frames at {size[0]}x{size[1]} ({frames} frames), "
          f"{a.workers} workers\n")
    print("| step | seconds | frames/s |\n|---|---:|---:|")
    print(f"| vtsbench build | {build_s:.1f} | {frames / build_s:.0f} |")
    print(f"| vtsbench export-hf | {export_s:.1f} | {frames / export_s:.0f} |")
    print(f"| export / build | {export_s / build_s:.2f} | |")
    print(f"| load_dataset's first call (parquet -> Arrow cache) | {prepare_s:.1f} | "
          f"{frames / prepare_s:.0f} |")
    print("\n| on disk | MB | % of raw | x Zarr |\n|---|---:|---:|---:|")
    print(f"| raw (uint8 rgb, float32 depth, bool contact) | {raw / 1e6:.1f} | 100.0 | |")
    for name, b in (("Zarr arrays (data/)", zarr_b), ("parquet copy (hf/)", hub_b),
                    ("Arrow cache of load_dataset (slip_all)", folder_bytes(cache))):
        print(f"| {name} | {b / 1e6:.1f} | {100 * b / raw:.1f} | {b / zarr_b:.2f} |")
    for col, b in sorted(column_bytes(root / HUB_DIR).items(), key=lambda kv: -kv[1]):
        if b > 1e5:
            print(f"| hf/ column `{col}` | {b / 1e6:.1f} | {100 * b / raw:.1f} | |")
    print("\n| reader (slip samples: rgb, depth, contact) | samples/s | x Zarr |\n"
          "|---|---:|---:|")
    for name, s in best.items():
        rate = len(view) / s
        print(f"| {name} | {rate:.1f} | {rate / base:.2f} |")
    print(f"\nmachine: {machine()}")


if __name__ == "__main__":
    main()
