"""Every way to read a built dataset, in one run, against the Zarr loader: samples/s, ratios, CPU.

Run: .venv/bin/python benchmarks/loader.py [--sequences 36] [--size 480x640] [--repeats 3]
     [--workers 2] [--dataset BUILT_DATASET] [--formats] [--torch-only]

Builds a dataset from simulated recordings (simulate, calibrate with lut, build: hf.py's
make_dataset) in a temporary folder, writes its Hugging Face copy (export-hf), then reads every
slip sample each way, the readers taking turns within each of --repeats rounds (best counts; the
page cache is warm, so this measures decoding, not the disk):

- the Zarr loader, `view.read([i], arrays)`, one sample per call in a shuffled order: rgb and
  depth (the baseline of the torch rows) and rgb, depth and contact (of the Hugging Face rows);
- `view.to_torch("rgbd")` through a shuffled DataLoader (batch 4, a new DataLoader each pass, so
  worker start-up counts) with 0 and --workers workers, at the stored size and resized to
  224x224, as uint8 frames (the default) and with dtype="float32" (the tensors of earlier
  versions, bit for bit: the before of the same run);
- `view.to_torch("rgbd").loader(batch_size=4, shuffle=True, num_workers=--workers)`: the same
  batches with the workers' batches written into reused shared memory (a new loader each pass;
  one loader iterated again, its workers new each pass, its shared memory kept; persistent
  workers), and what its main process pays to copy a batch out of its slot;
- `view.to_hf()`, streamed from the Zarr store (rgb, depth, contact as numpy);
- `datasets.load_dataset(DATASET, "slip_all")` after its cache is built, rows read by index in the
  same shuffled order, without a format (PIL images, made numpy) and with `.with_format("numpy")`,
  and the same with `streaming=True` (iterated);
- the first `load_dataset` call: seconds to build the Arrow cache, its bytes against the parquet's.

Every reader's arrays are checked against the loader's before timing. CPU is user + system time
per sample of the process and its children (DataLoader workers: those that ended, and the live
ones of a persistent DataLoader, read from /proc), with the workers' part apart: other jobs on a
shared machine slow the wall clock, not this. --formats adds the earlier format comparison (a
PNG folder and a parquet of Image() read through datasets); --torch-only times the Zarr loader
and the torch rows alone (no Hugging Face copy). Prints markdown tables and the machine;
removes everything it wrote.
"""

from __future__ import annotations

import argparse
import inspect
import os
import resource
import shutil
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from hf import column_bytes, folder_bytes, make_dataset  # benchmarks/hf.py
from machine import machine  # benchmarks/machine.py: the shared machine line

import vtsbench
from vtsbench.dataset.format.arrays import depth_to_int16
from vtsbench.dataset.format.layout import DEPTH_SCALE_MM
from vtsbench.dataset.read.view import View

Reader = Callable[[int], tuple[np.ndarray, np.ndarray]]
ALL = ("rgb", "depth", "contact")
SMALL = (224, 224)
#: Whether to_torch has dtype (uint8 frames); without it (earlier versions) it gives float32.
HAS_DTYPE = "dtype" in inspect.signature(View.to_torch).parameters


def cpu_s() -> tuple[float, float]:
    """User + system seconds of this process and of its children (DataLoader workers): the
    ended ones (getrusage) and the live ones (/proc/PID/stat: a persistent DataLoader's)."""
    import multiprocessing

    live = multiprocessing.active_children()  # reaps the ended ones first
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(
        resource.RUSAGE_CHILDREN)
    workers = kids.ru_utime + kids.ru_stime
    tick = os.sysconf("SC_CLK_TCK")
    for proc in live:
        try:
            stat = Path(f"/proc/{proc.pid}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        workers += (int(stat[11]) + int(stat[12])) / tick  # utime, stime
    return own.ru_utime + own.ru_stime, workers


# -- the readers --------------------------------------------------------------------------


def zarr_job(view: View, order: Sequence[int], arrays: Sequence[str]) -> Callable[[], int]:
    """The Zarr loader: one `view.read` per sample, in `order`."""
    def run() -> int:
        for i in order:
            view.read([i], arrays)
        return len(order)

    return run


def torch_job(view: View, modality: str, size: tuple[int, int] | None, workers: int,
              dtype: str, persistent: bool = False) -> Callable[[], int]:
    """One shuffled DataLoader pass (batch 4) over view.to_torch(modality): a new DataLoader
    each pass, so its workers start (and open the store) within it; or, persistent, one
    DataLoader whose workers stay (a later epoch of a training run), warmed up here."""
    import torch
    from torch.utils.data import DataLoader

    kw = {"dtype": dtype} if HAS_DTYPE else {}  # before dtype="uint8": float32 only
    data = view.to_torch(modality, size=size, **kw)

    def loader() -> Any:
        return DataLoader(data, batch_size=4, shuffle=True, num_workers=workers,
                          generator=torch.Generator().manual_seed(0),
                          persistent_workers=persistent)

    kept = loader() if persistent else None

    def run() -> int:
        return sum(len(t["sample_id"]) for _x, t in (kept or loader()))

    if kept is not None:
        run()
    return run


SLOT_MODES = {"new": "new each pass", "again": "one loader, workers new each pass",
              "persistent": "persistent (a later epoch)"}


def slots_job(view: View, workers: int, mode: str) -> Callable[[], int]:
    """One shuffled pass (batch 4) of view.to_torch("rgbd").loader(...): batches through
    reused shared memory; mode (SLOT_MODES) "new": a new loader each pass; "again": one
    loader, iterated again (new workers, its shared memory kept), warmed up; "persistent": one
    with persistent workers, warmed up."""
    import torch

    data = view.to_torch("rgbd")

    def loader() -> Any:
        return data.loader(batch_size=4, shuffle=True, num_workers=workers,
                           generator=torch.Generator().manual_seed(0),
                           persistent_workers=mode == "persistent")

    kept = loader() if mode != "new" else None

    def run() -> int:
        return sum(len(t["sample_id"]) for _x, t in (kept or loader()))

    if kept is not None:
        run()
    return run


def slot_copy(job: Callable[[], int], nbytes: int, repeats: int = 3) -> tuple[float, ...]:
    """What the main process of a slot loader pays: (CPU ms and page faults per sample over
    a pass of `job`, best of repeats; CPU ms and faults per sample to copy a batch of 4
    samples of nbytes, as rgb and depth, out of a slot, after a first copy)."""
    import torch

    from vtsbench.dataset.read.torch_loader import InSlot, unpack

    def faults() -> int:
        return resource.getrusage(resource.RUSAGE_SELF).ru_minflt

    best_cpu, best_faults = float("inf"), float("inf")
    for _ in range(repeats):
        c0, f0 = time.process_time(), faults()
        n = job()
        best_cpu = min(best_cpu, 1e3 * (time.process_time() - c0) / n)
        best_faults = min(best_faults, (faults() - f0) / n)
    ring = torch.UntypedStorage._new_shared(4 * nbytes + 128)
    ring_np = torch.from_numpy(np.empty(0, np.uint8)).set_(ring, 0, (4 * nbytes + 128,)).numpy()
    ring_np[:] = 7
    where = [InSlot(0, np.dtype(np.uint8), (4, nbytes * 3 // 7), (nbytes * 3 // 7, 1)),
             InSlot(4 * nbytes * 3 // 7 // 64 * 64 + 64, np.dtype(np.float32),
                    (4, nbytes // 7), (nbytes // 7, 1))]
    unpack(where, ring)
    copy_cpu, copy_faults = float("inf"), float("inf")
    for _ in range(5):
        c0, f0 = time.process_time(), faults()
        unpack(where, ring)
        copy_cpu = min(copy_cpu, 1e3 * (time.process_time() - c0) / 4)
        copy_faults = min(copy_faults, (faults() - f0) / 4)
    return best_cpu, best_faults, copy_cpu, copy_faults


def hf_row_arrays(row: dict[str, Any], scale_mm: float) -> dict[str, np.ndarray]:
    """A row of the hub copy (numpy format or PIL images, either layout) as the loader's
    arrays: rgb uint8, depth float32 mm, contact bool."""
    out = {}
    for name in ALL:
        v = row[name]
        a = np.stack([np.asarray(f) for f in v]) if isinstance(v, list) else np.asarray(v)
        if name == "depth":
            a = (a.view(np.int16).astype(np.float32) * np.float32(scale_mm)
                 if a.dtype == np.uint16 else a.astype(np.float32, copy=False))
        out[name] = a.astype(bool, copy=False) if name == "contact" else a
    return out


def rows_job(rows: Callable[[], Any], scale_mm: float) -> Callable[[], int]:
    """Every row of a datasets reader made into the loader's arrays."""
    def run() -> int:
        n = 0
        for r in rows():
            hf_row_arrays(r, scale_mm)
            n += 1
        return n

    return run


def shared_memory_ms(nbytes: int, repeats: int = 5) -> tuple[float, ...]:
    """CPU ms to move nbytes into torch's shared memory, as a DataLoader worker does with each
    batch: (allocate, allocate and write, the same with its pages prefaulted first by
    MADV_POPULATE_WRITE, write into fresh numpy memory, write into reused memory), best of
    repeats."""
    import ctypes

    import torch

    libc = ctypes.CDLL(None, use_errno=True)

    src = np.random.default_rng(0).integers(0, 255, nbytes, dtype=np.uint8)
    reused = np.empty_like(src)

    def shm(write: bool, populate: bool = False) -> None:
        t = torch.from_numpy(np.empty(0, np.uint8)).set_(
            torch.UntypedStorage._new_shared(nbytes), 0, (nbytes,))
        if populate:  # MADV_POPULATE_WRITE (Linux 5.14): fault every page in, in one call
            p = t.data_ptr()
            libc.madvise(ctypes.c_void_p(p & ~4095), ctypes.c_size_t(nbytes + p % 4096), 23)
        if write:
            np.copyto(t.numpy(), src)

    jobs = (lambda: shm(False), lambda: shm(True), lambda: shm(True, populate=True),
            lambda: np.copyto(np.empty_like(src), src), lambda: np.copyto(reused, src))
    out = []
    for job in jobs:
        job()
        b = float("inf")
        for _ in range(repeats):
            c0 = time.process_time()
            job()
            b = min(b, time.process_time() - c0)
        out.append(1e3 * b)
    return tuple(out)


def check_readers(view: View, order: Sequence[int], hf_rows: dict[str, Callable[[], Any]],
                  scale_mm: float) -> None:
    """Every reader gives the loader's arrays, sample by sample (before any timing)."""
    ids = view.ids
    want = {ids[i]: view.read([i], ALL) for i in order}
    for name, rows in hf_rows.items():
        seen = 0
        for r in rows():
            got = hf_row_arrays(r, scale_mm)
            ref = want[str(r["sample_id"])]
            for a in ALL:
                if not np.array_equal(got[a], ref[a][0]):
                    raise SystemExit(f"{name}: {a} of {r['sample_id']} differs from the loader")
            seen += 1
        if seen != len(order):
            raise SystemExit(f"{name}: {seen} rows, the loader has {len(order)}")
    x, t = view.to_torch("rgbd")[order[0]]
    rgb = x["rgb"] if isinstance(x, dict) else x[..., :3, :, :]
    ref = want[t["sample_id"]]
    if isinstance(x, dict) and not np.array_equal(np.moveaxis(rgb.numpy(), -3, -1),
                                                  ref["rgb"][0]):
        raise SystemExit("to_torch differs from the loader")


def best(jobs: dict[str, Callable[[], int]], n: int, repeats: int
         ) -> dict[str, tuple[float, float, float]]:
    """(samples/s, CPU ms per sample, of which in workers) of every job, best of repeats (the
    CPU of the repeat with the least); the jobs take turns within each repeat so that load
    from other processes falls on all of them alike."""
    wall = dict.fromkeys(jobs, float("inf"))
    cpu = dict.fromkeys(jobs, (float("inf"), 0.0))
    for _ in range(repeats):
        for key, job in jobs.items():
            t0, (m0, w0) = time.perf_counter(), cpu_s()
            got = job()
            w, (m1, w1) = time.perf_counter() - t0, cpu_s()
            if got != n:
                raise SystemExit(f"{key}: {got} samples, expected {n}")
            c = (m1 - m0 + w1 - w0, w1 - w0)
            wall[key], cpu[key] = min(wall[key], w), min(cpu[key], c)
    return {k: (n / wall[k], 1e3 * cpu[k][0] / n, 1e3 * cpu[k][1] / n) for k in jobs}


# -- the earlier format comparison (--formats) --------------------------------------------


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

    ds = datasets.Dataset.from_parquet(str(path), cache_dir=str(cache)).with_format("numpy")

    def read(i: int) -> tuple[np.ndarray, np.ndarray]:
        row = ds[i]
        rgb = np.stack(row["rgb"]).astype(np.uint8, copy=False)
        dep = np.stack(row["depth"]).astype(np.uint16, copy=False).view(np.int16)
        return rgb, dep.astype(np.float32) * np.float32(DEPTH_SCALE_MM)

    return read


def formats_report(view: View, work: Path, order: Sequence[int], repeats: int) -> list[str]:
    """The earlier comparison: the loader against a PNG folder and an Image() parquet."""
    n, frames = len(view), view.dataset.info.frames_per_sequence
    png_root = work / "png"
    write_png_folder(view, png_root)
    write_hf_parquet(png_root, view.ids, frames, work / "slip.parquet")
    readers: dict[str, Reader] = {
        "vtsbench loader (Zarr, zstd)": lambda i: tuple(view.read([i], ("rgb", "depth"))[a][0]
                                                        for a in ("rgb", "depth")),
        "PNG folder (OpenCV)": png_reader(png_root, view.ids, frames),
        "datasets parquet, Image() PNG (PIL)": hf_reader(work / "slip.parquet",
                                                         work / "hf-cache-read")}
    for name, read in readers.items():
        for i in order[:3]:
            a, b = read(i), view.read([i], ("rgb", "depth"))
            if not (np.array_equal(a[0], b["rgb"][0]) and np.array_equal(a[1], b["depth"][0])):
                raise SystemExit(f"{name} differs from the loader at sequence {i}")
    def job(read: Reader) -> Callable[[], int]:
        return lambda: sum(1 for i in order if read(i) is not None)

    jobs = {k: job(r) for k, r in readers.items()}
    rates = best(jobs, n, repeats)
    sizes = [folder_bytes(Path(view.dataset.location) / "data" / "slip.zarr"),
             folder_bytes(png_root), (work / "slip.parquet").stat().st_size]
    base = rates["vtsbench loader (Zarr, zstd)"][0]
    lines = ["", "| format (rgb + depth, shuffled) | on disk (MB) | samples/s | loader / this |",
             "|---|---:|---:|---:|"]
    for (name, (rate, _c, _w)), b in zip(rates.items(), sizes, strict=True):
        lines.append(f"| {name} | {b / 1e6:.0f} | {rate:.1f} | {base / rate:.1f}x |")
    return lines


# -- the run ------------------------------------------------------------------------------


def hf_setup(root: Path, work: Path, view: View, order: Sequence[int], workers: int
             ) -> tuple[dict[str, Callable[[], Any]], list[str]]:
    """Export the Hugging Face copy and build its Arrow cache: the Hugging Face readers, and
    the table of the copy's costs and sizes."""
    import datasets

    from vtsbench.dataset.format.layout import HUB_DIR
    from vtsbench.dataset.tools.hub import export_hf

    datasets.disable_progress_bars()
    t0 = time.perf_counter()
    export_hf(root, workers=workers)
    export_s = time.perf_counter() - t0
    cache = work / "cache"
    t0, c0 = time.perf_counter(), sum(cpu_s())
    arrow = datasets.load_dataset(str(root), "slip_all", split="full", cache_dir=str(cache))
    prepare_s, prepare_cpu = time.perf_counter() - t0, sum(cpu_s()) - c0
    files = sorted((root / HUB_DIR / "slip").glob("*.parquet"))
    parquet_b = sum(p.stat().st_size for p in files)
    cache_b = sum(p.stat().st_size for p in cache.rglob("*.arrow"))
    arrow_np = arrow.with_format("numpy")

    def stream(fmt: str | None) -> Any:
        s = datasets.load_dataset(str(root), "slip_all", split="full", streaming=True)
        return s if fmt is None else s.with_format(fmt)

    hf_rows: dict[str, Callable[[], Any]] = {
        "`view.to_hf()`, streamed from Zarr": lambda: view.to_hf(),
        "`load_dataset`, Arrow cache, no format (PIL images)": lambda: (arrow[i] for i in order),
        "`load_dataset`, Arrow cache, `.with_format(\"numpy\")`":
            lambda: (arrow_np[i] for i in order),
        "`load_dataset(streaming=True)`, no format": lambda: stream(None),
        "`load_dataset(streaming=True)`, `.with_format(\"numpy\")`": lambda: stream("numpy"),
    }
    lines = ["", "| Hugging Face copy | value |", "|---|---:|",
             f"| `vtsbench export-hf` (s) | {export_s:.1f} |",
             f"| first `load_dataset` (slip_all): Arrow cache build (s, wall / CPU) | "
             f"{prepare_s:.2f} / {prepare_cpu:.2f} |",
             f"| parquet it reads (MB) | {parquet_b / 1e6:.1f} |",
             f"| Arrow cache it writes (MB) | {cache_b / 1e6:.1f} |",
             f"| cache / parquet | {cache_b / parquet_b:.3f} |",
             f"| Zarr arrays, `data/slip.zarr` (MB) | "
             f"{folder_bytes(root / 'data' / 'slip.zarr') / 1e6:.1f} |"]
    for col, b in sorted(column_bytes(root / HUB_DIR / "slip").items(), key=lambda kv: -kv[1]):
        if b > 1e5:
            lines.append(f"| parquet column `{col}` (MB) | {b / 1e6:.1f} |")
    return hf_rows, lines


def run(work: Path, a: argparse.Namespace, size: tuple[int, int]) -> str:
    """Build (unless given a dataset), export (unless --torch-only), time every reader; returns
    the report."""
    load0 = os.getloadavg()[0]
    if a.dataset:
        root = work / "dataset"
        shutil.copytree(a.dataset, root)
        build_s = float("nan")
    else:
        root, build_s = make_dataset(work, a.sequences, 2, size, a.workers)
    ds = vtsbench.load(root)
    view = ds.slip
    n, scale = len(view), ds.info.depth_scale_mm
    order = [int(i) for i in np.random.default_rng(0).permutation(n)]
    hf_rows: dict[str, Callable[[], Any]] = {}
    hf_lines: list[str] = []
    if not a.torch_only:
        hf_rows, hf_lines = hf_setup(root, work, view, order, a.workers)
    check_readers(view, order, hf_rows, scale)
    base = {"rgb": "Zarr loader, rgb", "rgbd": "Zarr loader, rgb + depth",
            "all": "Zarr loader, rgb + depth + contact"}
    jobs: dict[str, Callable[[], int]] = {
        base["rgb"]: zarr_job(view, order, ("rgb",)),
        base["rgbd"]: zarr_job(view, order, ("rgb", "depth"))}
    if hf_rows:
        jobs[base["all"]] = zarr_job(view, order, ALL)
    torch_rows = []
    specs = [(m, None) for m in ("rgb", "rgbd")] + [("rgbd", SMALL)]
    for modality, sz in specs:
        for dtype in ("uint8", "float32") if HAS_DTYPE else ("float32",):
            for w, keep in ((0, False), (a.workers, False), (a.workers, True)):
                if keep and modality == "rgb":
                    continue
                args = "".join([f'"{modality}"', "" if sz is None else f", size={sz}",
                                ', dtype="float32"' if dtype == "float32" else ""])
                key = (f"`to_torch({args})`, DataLoader, {w} workers"
                       + (", persistent (a later epoch)" if keep else ""))
                jobs[key] = torch_job(view, modality, sz, w, dtype, keep)
                torch_rows.append((key, base[modality]))
    slots = hasattr(view.to_torch("rgbd"), "loader")  # earlier versions have no .loader
    if slots:
        for mode, text in SLOT_MODES.items():
            key = (f'`to_torch("rgbd").loader(batch_size=4, shuffle=True, '
                   f'num_workers={a.workers})`, reused shared memory, {text}')
            jobs[key] = slots_job(view, a.workers, mode)
            torch_rows.append((key, base["rgbd"]))
    for name, rows in hf_rows.items():
        jobs[name] = rows_job(rows, scale)
    rates = best(jobs, n, a.repeats)

    h, w = ds.info.resolution
    frames = ds.info.frames_per_sequence
    lines = [f"{n} slip samples of {frames} x {h} x {w} (rgb, depth, contact), shuffled order; "
             f"best of {a.repeats}; load average {load0:.1f} at the start.", "",
             "| reader | samples/s | / Zarr loader | CPU ms per sample (in workers) |",
             "|---|---:|---:|---:|"]

    def row(name: str, base: str) -> str:
        rate, cpu, workers = rates[name]
        cpu_text = f"{cpu:.0f}" + (f" ({workers:.0f})" if workers >= 0.5 else "")
        return f"| {name} | {rate:.1f} | {rate / rates[base][0]:.2f}x | {cpu_text} |"

    lines += [row(b, b) for b in base.values() if b in rates]
    lines += [row(k, b) for k, b in torch_rows]
    lines += [row(k, base["all"]) for k in hf_rows]
    nbytes = frames * h * w * (3 + 4)
    lines += ["", "Ratios: each torch row to the Zarr loader reading the same arrays, the "
              "others to it reading rgb + depth + contact. DataLoader batch 4; an rgbd sample at "
              f"{h}x{w} is "
              f"{nbytes / 1e6:.1f} MB as uint8 rgb + float32 mm depth, "
              f"{frames * h * w * 16 / 1e6:.1f} MB as float32. `vtsbench build`: "
              f"{build_s:.1f} s."]
    alloc, shm, populated, fresh, reused = shared_memory_ms(nbytes)
    lines += ["", f"Moving one rgbd sample ({nbytes / 1e6:.1f} MB) into torch's shared memory, "
              f"as a DataLoader worker does: {shm:.1f} ms of CPU ({alloc:.1f} ms allocating: "
              f"fallocate; then writing its 4 KB pages; {populated:.1f} ms with the pages "
              f"prefaulted by MADV_POPULATE_WRITE), against {fresh:.1f} ms into fresh "
              f"numpy memory and {reused:.1f} ms into reused memory."]
    if slots:
        main_ms, main_faults, copy_ms, copy_faults = slot_copy(jobs[torch_rows[-1][0]], nbytes)
        lines += ["", f"The main process of `.loader(...)` with {a.workers} persistent workers: "
                  f"{main_ms:.1f} ms of CPU and {main_faults:.0f} page faults a sample over a "
                  f"pass; copying a batch out of its slot {copy_ms:.1f} ms a sample "
                  f"({copy_faults:.0f} page faults: glibc reuses a freed buffer of up to 32 MB, "
                  f"a larger one, such as a batch's depth, is mapped afresh)."]
    lines += hf_lines
    if a.formats:
        lines += formats_report(view, work, order, a.repeats)
    lines += ["", f"Machine: {machine()}."]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sequences", type=int, default=36)
    ap.add_argument("--size", default="480x640")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--workers", type=int, default=2,
                    help="DataLoader workers, and the build's and export's workers.")
    ap.add_argument("--workdir", type=Path, default=None,
                    help="Folder for the files (default: a temporary one, removed at the end).")
    ap.add_argument("--dataset", type=Path, default=None,
                    help="Use a copy of this built dataset instead of building one.")
    ap.add_argument("--formats", action="store_true",
                    help="Also compare with a PNG folder and a parquet of Image() PNGs.")
    ap.add_argument("--torch-only", action="store_true",
                    help="Time the Zarr loader and the torch rows alone (no Hugging Face copy).")
    a = ap.parse_args()
    size = tuple(int(v) for v in a.size.lower().split("x"))
    work = Path(tempfile.mkdtemp(prefix="vtsbench-loader-", dir=a.workdir))
    try:
        print(run(work, a, (size[0], size[1])))
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
