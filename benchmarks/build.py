"""Build throughput and storage: frames/s of `vtsbench build`, and bytes on disk per compression.

Run: .venv/bin/python benchmarks/build.py [--static 120] [--sequences 120] [--size 480x640]
                                          [--recordings DIR] [--repeats 2] [--keep] [--level1]
                                          [--cli-only]

Simulates recordings (static frames, 8-frame sequences and 20 calibration presses) in a
temporary folder and calibrates them (lut), unless --recordings names a folder that already
has calibration.safetensors. Then:

1. builds the dataset with 1 and 2 worker processes (lut + dct, zstd level 3): frames/s end to
   end (checking the recordings, planning, shards, index, splits, preview, checksums) and of
   the shard phase alone (best of --repeats), the seconds before and after the shard phase
   (the fixed costs), the ratio of the two worker counts, and the CPU time per frame of the
   whole build (this process and its workers), with the CPU other processes used meanwhile
   (from /proc/stat: a shared machine shows in it); with --level1 also with 2 workers at zstd
   level 1; and `vtsbench build` itself, in a fresh process, with 1 and 2 workers;
2. times each stage of a shard task per frame in one process, as in a worker (decode, depth,
   contact mask, int16, encode and write), CPU time, and the parts of encoding a shard (zstd
   at levels 0, 1 and 3, crc32c, sha256);
3. re-encodes the built arrays with zstd levels 1, 3 and 9 and without compression: bytes on
   disk against raw (uint8 RGB + float32 depth), write speed (encode + write whole shards) and
   read speed (every sample through zarr), in frames/s, best of 2;
4. decodes 48 of the recordings' PNG frames with OpenCV (what vtsbench uses), pyspng and
   imagecodecs (each when installed), as written (Up rows), with Sub rows and with libpng's
   filter choice per row.

--cli-only runs only the fresh-process builds and 4 (at the demo's size, say:
`--recordings demo-data/recordings --cli-only`).

Prints markdown tables and the machine; removes everything it wrote (unless --keep).
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from vtsbench.dataset.build import execute, shard
from vtsbench.dataset.build import pipeline as build_mod
from vtsbench.dataset.build.pipeline import BuildOptions, build
from vtsbench.dataset.build.store import write_metadata, write_shard
from vtsbench.dataset.format.arrays import Layout
from vtsbench.dataset.format.layout import ARRAYS
from vtsbench.dataset.read.store import open_group
from vtsbench.recordings import manifest as manifest_mod


def machine() -> str:
    """Core count and CPU model (from /proc/cpuinfo where there is one)."""
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return (f"{os.cpu_count()} cores, {model}; Python {platform.python_version()}, "
            f"numpy {np.__version__}")


def make_recordings(root: Path, n_static: int, n_sequences: int, size: tuple[int, int]) -> None:
    """Simulated recordings plus a lut calibration, as `vtsbench calibrate` writes it."""
    from vtsbench.depth.calibration import calibrate, save_calibration
    from vtsbench.sim.simulate import simulate

    simulate(root, seed=0, n_static=n_static, n_sequences=n_sequences, n_presses=20, size=size,
             mm_per_px=0.03, n_sessions=2, workers=2, progress=False)
    run = calibrate(root, method="lut", device=None)
    save_calibration(run.calibration, root / "calibration.safetensors")


def _cpu_seconds() -> float:
    """User + system CPU seconds of this process and its finished children."""
    import resource

    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(
        resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def _busy_seconds() -> float:
    """CPU seconds all processes of the machine have used (from /proc/stat; 0 elsewhere)."""
    try:
        fields = Path("/proc/stat").read_text().splitlines()[0].split()[1:]
    except OSError:
        return 0.0
    user, nice, system, _idle, _iowait, irq, softirq, steal = (int(v) for v in fields[:8])
    return (user + nice + system + irq + softirq + steal) / os.sysconf("SC_CLK_TCK")


def timed_build(rec: Path, out: Path, workers: int, repeats: int,
                level: int = 3) -> dict[str, float]:
    """Best of `repeats` builds: total seconds, seconds in the shard phase and before it, CPU
    seconds, frames."""
    phase = {"shards": 0.0, "start": 0.0}
    real = build_mod.run_with_progress

    def run(*args: Any, **kwargs: Any) -> Any:
        t0 = time.perf_counter()
        phase["start"] = phase["start"] or t0
        try:
            return real(*args, **kwargs)
        finally:
            phase["shards"] += time.perf_counter() - t0

    best: dict[str, float] = {}
    build_mod.run_with_progress = run  # type: ignore[assignment]
    try:
        for _ in range(repeats):
            phase["shards"] = phase["start"] = 0.0
            shutil.rmtree(out, ignore_errors=True)  # a fresh build: deleting is not its work
            getattr(manifest_mod, "_VALIDATED", {}).clear()  # validate as a fresh build does
            b0, c0, t0 = _busy_seconds(), _cpu_seconds(), time.perf_counter()
            res = build(rec, out, BuildOptions(workers=workers, compression_level=level))
            total, cpu = time.perf_counter() - t0, _cpu_seconds() - c0
            others = max(0.0, _busy_seconds() - b0 - cpu) / total
            if not best or total < best["total"]:
                before = phase["start"] - t0
                best = {"total": total, "shards": phase["shards"], "cpu": cpu,
                        "frames": sum(res.frames.values()), "others": others,
                        "before": before, "after": total - before - phase["shards"]}
    finally:
        build_mod.run_with_progress = real  # type: ignore[assignment]
    return best


def timed_cli(rec: Path, out: Path, workers: int, repeats: int) -> dict[str, float]:
    """Best of `repeats` runs of `vtsbench build REC OUT --workers N` in a fresh process, as a
    user runs it: Python's start, every import and the whole build; wall and CPU seconds (the
    process and its workers)."""
    import resource
    import subprocess

    best: dict[str, float] = {}
    for _ in range(repeats):
        shutil.rmtree(out, ignore_errors=True)
        kids = resource.getrusage(resource.RUSAGE_CHILDREN)
        b0, t0 = _busy_seconds(), time.perf_counter()
        done = subprocess.run([sys.executable, "-m", "vtsbench", "build", str(rec), str(out),
                               "--workers", str(workers)], check=True, capture_output=True,
                              text=True)
        total = time.perf_counter() - t0
        frames = re.search(r"(\d+) frames in", done.stdout + done.stderr)
        k = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = k.ru_utime + k.ru_stime - kids.ru_utime - kids.ru_stime
        others = max(0.0, _busy_seconds() - b0 - cpu) / total
        if not best or total < best["total"]:
            best = {"total": total, "cpu": cpu, "others": others,
                    "frames": int(frames.group(1)) if frames else float("nan")}
    shutil.rmtree(out, ignore_errors=True)
    return best


def stage_times(rec: Path, work: Path, n_sequences: int = 24) -> dict[str, float]:
    """CPU ms per frame of each stage of a shard task, in this process as in a worker (one
    OpenCV thread, malloc keeping freed memory): decode, depth (colour difference, lut, dct),
    contact mask, int16, and encode + write (zstd, crc32c, sha256, files), for shards of four
    8-frame sequences at level 3; each stage's best shard (the machine is shared). The first
    shard warms up (imports, caches, FFT plans)."""
    import cv2

    from vtsbench.dataset.build.store import write_shard
    from vtsbench.dataset.format.arrays import depth_to_int16
    from vtsbench.depth.calibration import load_calibration
    from vtsbench.recordings.manifest import load_manifest
    from vtsbench.recordings.media import read_frames

    cv2.setNumThreads(1)
    cal = load_calibration(rec / "calibration.safetensors")
    mk = shard._maker(cal)
    seqs = [e for e in load_manifest(rec).entries if e.kind == "sequence"][:n_sequences + 4]
    names = ("decode", "depth", "contact", "int16", "encode + write")
    best = dict.fromkeys(names, float("inf"))
    lay = Layout("slip", len(seqs), cal.resolution, 8, 4, 3)
    group = work / "stages"
    with execute._malloc_keeps_memory():
        for n in range(0, len(seqs) - 3, 4):
            t = dict.fromkeys(names, 0.0)
            t0 = time.process_time()
            rgb = np.empty((4, 8, *cal.resolution, 3), np.uint8)
            for i, e in enumerate(seqs[n:n + 4]):  # as run_shard: into the shard's rows
                x = _read_into(read_frames, rec / e.source.path, e.source.start or 0,
                               (e.source.start or 0) + 8, rgb[i])
                if x is not rgb[i]:
                    rgb[i] = x
            t1 = time.process_time()
            depth = np.empty(rgb.shape[:-1], np.int16)
            contact = np.empty(rgb.shape[:-1], bool)
            for i in range(4):
                for f in range(8):
                    ta = time.process_time()
                    diff = mk.difference(rgb[i, f])
                    z = mk.integrate(mk.gradients(diff), "dct")
                    tb = time.process_time()
                    contact[i, f] = mk.contact(diff)
                    tc = time.process_time()
                    depth_to_int16(z, out=depth[i, f], scratch=True)
                    td = time.process_time()
                    t["depth"] += tb - ta
                    t["contact"] += tc - tb
                    t["int16"] += td - tc
            t4 = time.process_time()
            write_shard(group, lay, n // 4, {"rgb": rgb, "depth": depth, "contact": contact},
                        {})  # new files, as in a build (replacing one costs more here)
            t5 = time.process_time()
            t["decode"] += t1 - t0
            t["encode + write"] += t5 - t4
            if n:  # the first shard warms up
                frames = rgb.shape[0] * rgb.shape[1]
                best = {k: min(best[k], t[k] / frames * 1000) for k in names}
    shutil.rmtree(group, ignore_errors=True)
    return best


def _read_into(read_frames: Any, path: Path, start: int, stop: int, out: np.ndarray) -> Any:
    """read_frames into out where it takes out= (this code), else as the code before it."""
    try:
        return read_frames(path, start, stop, out=out)
    except TypeError:
        return read_frames(path, start, stop)


def encode_parts(ds: Path) -> dict[str, float]:
    """CPU ms per frame of the parts of encoding a slip shard (rgb, depth, contact): zstd at
    levels 0 (none), 1 and 3, and the crc32c and sha256 of the level-3 bytes; best of 5."""
    import hashlib

    import google_crc32c
    from numcodecs import Zstd

    g = open_group(ds, "slip")
    sps = g["rgb"].shards[0]
    blocks = {n: g[n][:sps] for n in ARRAYS}
    frames = blocks["rgb"].shape[0] * blocks["rgb"].shape[1]
    out: dict[str, float] = {}

    def best(fn: Any) -> float:
        b = float("inf")
        for _ in range(5):
            t0 = time.process_time()
            fn()
            b = min(b, time.process_time() - t0)
        return b / frames * 1000

    chunks = {}
    for level in (0, 1, 3):
        z = Zstd(level=level) if level else None

        def enc(z: Any = z) -> list[bytes]:
            return [z.encode(np.ascontiguousarray(c)) if z else c.tobytes()
                    for n in ARRAYS for c in blocks[n]]

        out[f"zstd {level}" if level else "no compression"] = best(enc)
        chunks[level] = enc()
    data = chunks[3]
    out["crc32c"] = best(lambda: [google_crc32c.value(c) for c in data])
    joined = b"".join(data)
    out["sha256"] = best(lambda: hashlib.sha256(joined).hexdigest())
    return out


def _decoders() -> dict[str, Any]:
    """PNG bytes -> RGB uint8 with each library that is installed: OpenCV (what vtsbench uses),
    libspng through pyspng, and imagecodecs (libpng or libspng inside)."""
    import cv2

    out: dict[str, Any] = {"OpenCV imdecode": lambda b: cv2.imdecode(
        np.frombuffer(b, np.uint8), cv2.IMREAD_COLOR_RGB)}
    try:
        import pyspng

        out["pyspng"] = lambda b: pyspng.load(b)
    except ImportError:
        pass
    try:
        import imagecodecs

        out["imagecodecs png_decode"] = lambda b: imagecodecs.png_decode(b)
    except ImportError:
        pass
    return out


def png_decoding(rec: Path, work: Path, n_frames: int = 48) -> list[dict[str, Any]]:
    """CPU ms per frame of decoding the recordings' PNG frames (bytes already read) with each
    installed library, the same files in the same run (best of 3, one OpenCV thread), for the
    frames as written (Up rows), re-encoded with Sub rows and with libpng's filter choice per
    row; and whether every library gives the same pixels."""
    import cv2

    cv2.setNumThreads(1)
    files = sorted((rec / "sequences").rglob("*.png"))[:n_frames]
    tmp = work / "png-filters"
    variants = {"Up (as vtsbench writes)": files}
    for name, folder, flag in (("Sub", "sub", cv2.IMWRITE_PNG_FILTER_SUB),
                               ("libpng's choice per row", "adaptive", None)):
        out = tmp / folder
        out.mkdir(parents=True, exist_ok=True)
        params = [cv2.IMWRITE_PNG_COMPRESSION, 1,
                  cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY]
        if flag is not None:
            params += [cv2.IMWRITE_PNG_FILTER, flag]
        paths = []
        for i, f in enumerate(files):
            p = out / f"{i:04d}.png"
            cv2.imwrite(str(p), cv2.imread(str(f), cv2.IMREAD_UNCHANGED), params)
            paths.append(p)
        variants[name] = paths

    def best(fn: Any, blobs: list[bytes]) -> float:
        b = float("inf")
        for _ in range(3):
            t0 = time.process_time()
            for d in blobs:
                fn(d)
            b = min(b, time.process_time() - t0)
        return b / len(blobs) * 1000

    decoders = _decoders()
    rows = []
    for name, paths in variants.items():
        blobs = [p.read_bytes() for p in paths]
        ms = {lib: best(fn, blobs) for lib, fn in decoders.items()}
        ref = [decoders["OpenCV imdecode"](d) for d in blobs]
        same = all(np.array_equal(np.asarray(fn(d))[..., :3], r)
                   for fn in decoders.values() for d, r in zip(blobs, ref, strict=True))
        rows.append({"filter": name, "kB": np.mean([len(d) for d in blobs]) / 1000,
                     "ms": ms, "n": len(paths), "same": same})
    shutil.rmtree(tmp, ignore_errors=True)
    return rows


def storage(ds: Path, work: Path, levels: list[int]) -> list[dict[str, float]]:
    """Re-encode the built arrays at each level: bytes, write and read frames/s (best of 2)."""
    data, layouts = {}, {}
    for kind in ("static", "slip"):
        g = open_group(ds, kind)
        data[kind] = {n: g[n][:] for n in ARRAYS}
        n, frames = data[kind]["rgb"].shape[0], data[kind]["rgb"].shape[1] if kind == "slip" \
            else None
        layouts[kind] = (n, frames, g["rgb"].shards[0], data[kind]["rgb"].shape[-3:-1])
    n_frames = sum(int(np.prod(d["depth"].shape[:-2])) for d in data.values())
    raw = sum(d["rgb"].nbytes + d["depth"].size * 4 for d in data.values())
    rows = []
    for level in levels:
        best_w = best_r = float("inf")
        size = 0
        for _ in range(2):
            out = work / f"level{level}"
            shutil.rmtree(out, ignore_errors=True)
            t0 = time.perf_counter()
            for kind, (n, frames, sps, hw) in layouts.items():
                lay = Layout(kind, n, tuple(hw), frames, sps, level)
                group = out / "data" / f"{kind}.zarr"
                write_metadata(group, lay)
                for k in range(lay.n_shards):
                    r = lay.shard_rows(k)
                    write_shard(group, lay, k, {a: data[kind][a][r.start:r.stop] for a in ARRAYS})
            best_w = min(best_w, time.perf_counter() - t0)
            size = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
            t0 = time.perf_counter()
            for kind in layouts:
                g = open_group(out, kind)
                for a in ARRAYS:
                    arr = g[a]
                    for i in range(arr.shape[0]):
                        arr[i]
            best_r = min(best_r, time.perf_counter() - t0)
        shutil.rmtree(work / f"level{level}", ignore_errors=True)
        rows.append({"level": level, "bytes": size, "raw": raw, "write": n_frames / best_w,
                     "read": n_frames / best_r, "frames": n_frames})
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    # 1,080 frames: enough that the fixed costs (imports, checking, finishing; about 2 s of CPU)
    # weigh little, as at the paper's scale (83,000 frames)
    ap.add_argument("--static", type=int, default=120)
    ap.add_argument("--sequences", type=int, default=120)
    ap.add_argument("--size", default="480x640")
    ap.add_argument("--recordings", type=Path, default=None,
                    help="use this recordings folder (with calibration.safetensors)")
    ap.add_argument("--repeats", type=int, default=2, help="builds per worker count (best)")
    ap.add_argument("--keep", action="store_true", help="keep the temporary folder")
    ap.add_argument("--level1", action="store_true",
                    help="also build with 2 workers at zstd level 1")
    ap.add_argument("--cli-only", action="store_true",
                    help="only `vtsbench build` in a fresh process (1 and 2 workers) and the "
                         "PNG decoding")
    args = ap.parse_args()
    size = tuple(int(v) for v in args.size.lower().split("x"))
    work = Path(tempfile.mkdtemp(prefix="vtsbench-bench-build-"))
    try:
        rec = args.recordings
        if rec is None:
            rec = work / "recordings"
            t0 = time.perf_counter()
            make_recordings(rec, args.static, args.sequences, size)  # type: ignore[arg-type]
            print(f"simulated and calibrated in {time.perf_counter() - t0:.1f} s",
                  file=sys.stderr)
        decoding = png_decoding(rec, work)
        cli = {w: timed_cli(rec, work / "ds-cli", w, args.repeats) for w in (1, 2)}
        if args.cli_only:
            report_cli(cli)
            report_png(decoding)
            print(f"\nMachine: {machine()}")
            return
        runs: dict[Any, dict[str, float]] = {
            w: timed_build(rec, work / f"ds{w}", w, args.repeats) for w in (1, 2)}
        if args.level1:  # the same build at zstd level 1 (not the default), 2 workers
            runs["2, zstd level 1"] = timed_build(rec, work / "ds-l1", 2, args.repeats, level=1)
            shutil.rmtree(work / "ds-l1", ignore_errors=True)
        stages = stage_times(rec, work)
        parts = encode_parts(work / "ds1")
        rows = storage(work / "ds1", work, [0, 1, 3, 9])
        report(runs, cli, stages, parts, rows, size)  # type: ignore[arg-type]
        report_png(decoding)
        print(f"\nMachine: {machine()}")
    finally:
        if args.keep:
            print(f"kept {work}", file=sys.stderr)
        else:
            shutil.rmtree(work, ignore_errors=True)


def report(runs: dict[Any, dict[str, float]], cli: dict[int, dict[str, float]],
           stages: dict[str, float],
           parts: dict[str, float], rows: list[dict[str, float]],
           size: tuple[int, int]) -> None:
    """Markdown tables."""
    h, w = size
    n = int(runs[1]["frames"])
    print(f"### Build throughput ({h}x{w}, {n} frames, lut + dct, zstd level 3)\n")
    print("| workers | end to end (s) | frames/s end to end | shard phase (s) "
          "| frames/s in the shard phase | before / after the shards (s) | CPU ms per frame "
          "| other processes (cores) |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|")
    for k, r in runs.items():
        print(f"| {k} | {r['total']:.1f} | {r['frames'] / r['total']:.1f} | {r['shards']:.1f} "
              f"| {r['frames'] / r['shards']:.1f} | {r['before']:.2f} / {r['after']:.2f} "
              f"| {r['cpu'] / r['frames'] * 1000:.1f} | {r['others']:.2f} |")
    print(f"\n2 workers / 1 worker: {runs[1]['total'] / runs[2]['total']:.2f}x end to end, "
          f"{runs[1]['shards'] / runs[2]['shards']:.2f}x in the shard phase. (Builds in this "
          "process after the first: imports done; the first build's are in the next table.)\n")
    report_cli(cli)
    print()
    print("### Per frame, one process (ms)\n")
    print("| " + " | ".join(stages) + " | total |")
    print("|" + "---:|" * (len(stages) + 1))
    print("| " + " | ".join(f"{v:.1f}" for v in stages.values())
          + f" | {sum(stages.values()):.1f} |")
    print("\n### Encoding a slip shard, per frame (CPU ms; rgb + depth + contact)\n")
    print("| " + " | ".join(parts) + " |")
    print("|" + "---:|" * len(parts))
    print("| " + " | ".join(f"{v:.2f}" for v in parts.values()) + " |")
    print("\n### Storage (bytes against raw uint8 RGB + float32 depth)\n")
    print("| compression | on disk (MB) | raw (MB) | on disk / raw | write (frames/s) "
          "| read (frames/s) |")
    print("|---|---:|---:|---:|---:|---:|")
    for r in rows:
        name = f"zstd level {r['level']}" if r["level"] else "none (crc32c only)"
        print(f"| {name} | {r['bytes'] / 1e6:.1f} | {r['raw'] / 1e6:.1f} | "
              f"{r['bytes'] / r['raw']:.1%} | {r['write']:.0f} | {r['read']:.0f} |")


def report_cli(cli: dict[int, dict[str, float]]) -> None:
    """The fresh-process builds' table."""
    n = int(next(iter(cli.values()))["frames"])
    print(f"`vtsbench build REC OUT --workers N` in a fresh process (Python's start and all "
          f"imports included), {n} frames:\n")
    print("| workers | wall (s) | frames/s | CPU ms per frame | other processes (cores) |")
    print("|---:|---:|---:|---:|---:|")
    for k, r in cli.items():
        print(f"| {k} | {r['total']:.1f} | {n / r['total']:.1f} | {r['cpu'] / n * 1000:.1f} "
              f"| {r['others']:.2f} |")


def report_png(rows: list[dict[str, Any]]) -> None:
    """The PNG decoding table: CPU ms a frame per library, and the ratio to OpenCV."""
    libs = list(rows[0]["ms"]) if rows else []
    print("\n### Decoding the recordings' PNG frames, CPU ms a frame (one core)\n")
    print("| rows filtered | kB a frame | " + " | ".join(libs) + " | OpenCV / fastest other "
          "| same pixels |")
    print("|---|---:|" + "---:|" * len(libs) + "---:|---|")
    for r in rows:
        others = [v for k, v in r["ms"].items() if k != "OpenCV imdecode"]
        ratio = f"{r['ms']['OpenCV imdecode'] / min(others):.2f}x" if others else "-"
        print(f"| {r['filter']} | {r['kB']:.0f} | "
              + " | ".join(f"{v:.2f}" for v in r["ms"].values())
              + f" | {ratio} | {'yes' if r['same'] else 'NO'} |")


if __name__ == "__main__":
    main()
