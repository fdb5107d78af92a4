"""A real take stored once as an episode, against today's build of it as 8-frame windows.

Run: .venv/bin/python benchmarks/episodes.py [--video PATH] [--fps 25] [--keep] [--no-sim]

The default take is ../shared/data/real/incipient_slip_sample/blue_mug/exp_num_1/camera_0.avi
(GelSight Mini, 320x240, 25 fps); any video works with --video. Without the file the benchmark
says so and stops (exit 0).

In a temporary folder:
1. decodes the video (vtsbench.recordings.media.read_frames; frame k at k / fps) and writes it
   with `vtsbench.create` as one episode (arrays rgb, zstd level 3, as a build);
2. reads from that one store, with no rebuild: windows of 8 frames at stride 8, of 16 frames at
   stride 1, and by delta_timestamps (the 8 frames of the last 0.28 s, LeRobot style), every
   window of each once, batched (`windows.read`);
3. builds the same take today's way with the command line: `vtsbench manifest` of the video as
   a slip take cut into windows of 8 frames at stride 1 and at stride 8, then
   `vtsbench build --no-depth` of each;
4. builds the same manifests with `vtsbench build --store episodes` (each take stored once,
   the windows views of it: format 1.3);
5. simulates a small recordings folder with a calibration (`vtsbench.sim.simulate`, lut
   calibration: RGB-D), its sequences cut into windows of 8 at stride 8 (the simulator's own
   manifest) and at stride 1 (the manifest rewritten), and builds each with --store samples
   and --store episodes;
6. prints the bytes on disk of each dataset (the whole folder and its data/) and the build
   seconds as markdown tables, and the machine.

Removes everything it wrote unless --keep.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from hf import folder_bytes  # benchmarks/hf.py
from machine import machine  # benchmarks/machine.py: the shared machine line

import vtsbench
from vtsbench.recordings.media import read_frames

ROOT = Path(__file__).resolve().parent.parent
DEFAULT = (ROOT.parent / "shared" / "data" / "real" / "incipient_slip_sample" / "blue_mug"
           / "exp_num_1" / "camera_0.avi")


def vts(*args: str) -> float:
    """Run `vtsbench ARGS` in a fresh process; seconds it took (a failure stops here)."""
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, "-m", "vtsbench", *args], capture_output=True,
                         text=True)
    if res.returncode:
        raise SystemExit(f"vtsbench {' '.join(args)} failed:\n{res.stderr[-2000:]}")
    return time.perf_counter() - t0


def write_episode(video: Path, out: Path, fps: float) -> tuple[int, float]:
    """The take as one episode; (frames, seconds to decode and write)."""
    t0 = time.perf_counter()
    frames = read_frames(video)
    with vtsbench.create(out, fps=fps, sensor="gelsight-mini", name="take") as w:
        w.add_episode(frames, object=video.parent.parent.name or "object", session="s0",
                      source=video.name)
    return len(frames), time.perf_counter() - t0


def read_windows(out: Path) -> list[tuple[str, int, int, float]]:
    """(what, windows, frames each, seconds to read every one: best of 2) of three kinds of
    windows of one store."""
    eps = vtsbench.load(out).episodes
    eps[0]  # the store opened and the file cache warm: the timings below are reading
    rows = []
    for what, win in (
            ("8 frames, stride 8", eps.windows(8, 8)),
            ("16 frames, stride 1", eps.windows(16, 1)),
            ("delta_timestamps -0.28..0 s (8)", eps.windows(
                delta_timestamps=[-0.28 + 0.04 * k for k in range(8)]))):
        best = float("inf")
        for _ in range(2):  # best of 2
            t0 = time.perf_counter()
            for start in range(0, len(win), 64):
                batch = win.read(slice(start, start + 64))
                assert batch["rgb"].shape[1] == win.length
            best = min(best, time.perf_counter() - t0)
        rows.append((what, len(win), win.length, best))
    return rows


def build_windows(video: Path, work: Path, stride: int, store: str = "samples"
                  ) -> tuple[Path, float, float]:
    """Today's build of the take: manifest windows of 8 at `stride`, build --no-depth with
    --store STORE; (dataset, seconds of manifest + build, seconds of the build alone)."""
    src = work / "src"
    src.mkdir(exist_ok=True)
    link = src / f"{video.parent.parent.name or 'object'}_1{video.suffix}"
    if not link.exists():
        link.symlink_to(video.resolve())
    rec, out = work / f"rec-stride{stride}", work / f"built-stride{stride}-{store}"
    secs = 0.0
    if not rec.exists():
        secs = vts("manifest", str(src), "--pattern", "{object}_{take:d}" + video.suffix,
                   "--sensor", "gelsight-mini", "--window", "8", "--stride", str(stride),
                   "--out", str(rec))
    b = vts("build", str(rec), str(out), "--no-depth", "--quiet", "--store", store)
    return out, secs + b, b


def simulated(work: Path) -> dict[int, Path]:
    """A simulated RGB-D recordings folder (6 static frames, 6 takes of 32 frames at 240x320,
    6 presses, lut calibration) whose takes are cut into windows of 8 at stride 8 (the
    simulator's manifest) and at stride 1 (the same folder, the manifest rewritten)."""
    from dataclasses import replace

    from vtsbench.depth.calibration import calibrate, save_calibration
    from vtsbench.recordings.manifest import Source, load_manifest, save_manifest
    from vtsbench.sim.simulate import simulate

    rec8 = work / "sim-stride8"
    simulate(rec8, seed=0, n_static=6, n_sequences=6, n_presses=6, size=(240, 320),
             frames=32, mm_per_px=0.06, progress=False)
    run = calibrate(rec8, method="lut", device="cpu")
    save_calibration(run.calibration, rec8 / "calibration.safetensors")
    rec1 = Path(shutil.copytree(rec8, work / "sim-stride1", symlinks=True))
    m = load_manifest(rec1)
    entries = []
    for e in m.entries:
        if e.kind != "sequence":
            entries.append(e)
            continue
        a, b = e.source.start or 0, e.source.stop
        entries += [replace(e, id=f"{e.id}-s{k:03d}", source=Source(e.source.path, start=k,
                                                                     stop=k + 8))
                    for k in range(a, b - 7)]
    m.entries = entries
    save_manifest(rec1, m)
    return {8: rec8, 1: rec1}


def size_rows(label: str, built: dict[tuple[int, str], tuple[Path, float]]) -> None:
    """Markdown table: bytes and build seconds of --store samples and episodes per stride."""
    print("| recordings | store | samples (static + slip) | frames stored | data/ | "
          "whole folder | vs samples | build |")
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for (stride, store), (out, secs) in sorted(built.items(), key=lambda x: (-x[0][0],
                                                                             x[0][1] != "samples")):
        ds = vtsbench.load(out)
        stored = (len(ds.episodes.frames) if store == "episodes" and len(ds.episodes)
                  else len(ds.slip) * 8 + len(ds.static))
        total, data = folder_bytes(out), folder_bytes(out / "data")
        base = folder_bytes(built[(stride, "samples")][0])
        print(f"| {label}, windows of 8 at stride {stride} | `--store {store}` | "
              f"{len(ds.static)} + {len(ds.slip)} | {stored} | {data / 1e6:.2f} MB | "
              f"{total / 1e6:.2f} MB | {total / base:.2f}x | {secs:.1f} s |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--video", type=Path, default=DEFAULT, help="a take (any video)")
    ap.add_argument("--fps", type=float, default=25.0, help="its frame rate")
    ap.add_argument("--keep", action="store_true", help="keep the datasets")
    ap.add_argument("--no-sim", action="store_true", help="skip the simulated recordings")
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="vtsbench-episodes-"))
    try:
        if not args.no_sim:
            print("Samples as views of the episodes: `vtsbench build --store samples` against "
                  "`--store episodes` of the same manifest (build seconds of the command, "
                  "one worker).\n")
            recs = simulated(work)
            sim = {(s, store): (work / f"sim-built-{s}-{store}", vts(
                "build", str(rec), str(work / f"sim-built-{s}-{store}"), "--quiet", "--store",
                store)) for s, rec in recs.items() for store in ("samples", "episodes")}
            size_rows("simulated RGB-D (6 takes of 32 frames, 240x320)", sim)
        if not args.video.is_file():
            print(f"skipped the real take: {args.video} not found (the real data is absent); "
                  "give one with --video PATH")
            print(f"\nMachine: {machine()}.")
            return
        ep_out = work / "episode"
        n, ep_secs = write_episode(args.video, ep_out, args.fps)
        reads = read_windows(ep_out)
        made = {(s, store): build_windows(args.video, work, s, store)
                for s in (1, 8) for store in ("samples", "episodes")}
        built = {s: made[(s, "samples")][:2] for s in (1, 8)}
        both = {k: (v[0], v[2]) for k, v in made.items()}
        ep_total, ep_data = folder_bytes(ep_out), folder_bytes(ep_out / "data")
        print(f"Take: {args.video.name} of {args.video.parent.parent.name}/"
              f"{args.video.parent.name}, {n} frames at {args.fps:g} fps.\n")
        print("| dataset | frames stored | data/ | data/ per frame | whole folder | "
              "vs the episode |")
        print("|---|---:|---:|---:|---:|---:|")
        print(f"| episode (`vtsbench.create`, {ep_secs:.1f} s) | {n} | {ep_data / 1e6:.2f} MB "
              f"| {ep_data / n / 1e3:.1f} KB | {ep_total / 1e6:.2f} MB | 1.00x |")
        for s, (out, secs) in built.items():
            ds = vtsbench.load(out)
            stored = len(ds.slip) * 8
            total, data = folder_bytes(out), folder_bytes(out / "data")
            print(f"| 8-frame windows at stride {s} (`manifest` + `build --no-depth`, "
                  f"{secs:.1f} s) | {stored} | {data / 1e6:.2f} MB | "
                  f"{data / stored / 1e3:.1f} KB | {total / 1e6:.2f} MB | "
                  f"{total / ep_total:.2f}x |")
        print("\nThe same manifests built with `--store samples` and `--store episodes` "
              "(build seconds of the command alone):\n")
        size_rows(f"real take {args.video.name} ({n} frames, RGB)", both)
        print("\nWindows read from the one episode store, no rebuild (every window once, "
              "batches of 64, best of 2):\n")
        print("| windows | count | read all | windows/s | frames out/s |")
        print("|---|---:|---:|---:|---:|")
        for what, count, t, secs in reads:
            rate = count / max(secs, 1e-9)
            print(f"| {what} | {count} | {secs:.2f} s | {rate:.0f} | {rate * t:.0f} |")
        print(f"\nMachine: {machine()}.")
        if args.keep:
            print(f"kept in {work}")
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
