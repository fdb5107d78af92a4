"""A real take stored once as an episode, against today's build of it as 8-frame windows.

Run: .venv/bin/python benchmarks/episodes.py [--video PATH] [--fps 25] [--keep]

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
4. prints the bytes on disk of each dataset (the whole folder and its data/) as a markdown
   table, and the machine.

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

from machine import machine  # benchmarks/machine.py: the shared machine line

import vtsbench
from vtsbench.recordings.media import read_frames

ROOT = Path(__file__).resolve().parent.parent
DEFAULT = (ROOT.parent / "shared" / "data" / "real" / "incipient_slip_sample" / "blue_mug"
           / "exp_num_1" / "camera_0.avi")


def folder_bytes(path: Path, under: str = "") -> int:
    """Bytes of the files under a folder (or its sub-folder `under`)."""
    base = path / under if under else path
    return sum(p.stat().st_size for p in base.rglob("*") if p.is_file())


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


def build_windows(video: Path, work: Path, stride: int) -> tuple[Path, float]:
    """Today's build of the take: manifest windows of 8 at `stride`, build --no-depth."""
    src = work / "src"
    src.mkdir(exist_ok=True)
    link = src / f"{video.parent.parent.name or 'object'}_1{video.suffix}"
    if not link.exists():
        link.symlink_to(video.resolve())
    rec, out = work / f"rec-stride{stride}", work / f"built-stride{stride}"
    secs = vts("manifest", str(src), "--pattern", "{object}_{take:d}" + video.suffix,
               "--sensor", "gelsight-mini", "--window", "8", "--stride", str(stride),
               "--out", str(rec))
    secs += vts("build", str(rec), str(out), "--no-depth", "--quiet")
    return out, secs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--video", type=Path, default=DEFAULT, help="a take (any video)")
    ap.add_argument("--fps", type=float, default=25.0, help="its frame rate")
    ap.add_argument("--keep", action="store_true", help="keep the datasets")
    args = ap.parse_args()
    if not args.video.is_file():
        print(f"skipped: {args.video} not found (the real data is absent); give a take with "
              "--video PATH")
        return
    work = Path(tempfile.mkdtemp(prefix="vtsbench-episodes-"))
    try:
        ep_out = work / "episode"
        n, ep_secs = write_episode(args.video, ep_out, args.fps)
        reads = read_windows(ep_out)
        built = {s: build_windows(args.video, work, s) for s in (1, 8)}
        ep_total, ep_data = folder_bytes(ep_out), folder_bytes(ep_out, "data")
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
            total, data = folder_bytes(out), folder_bytes(out, "data")
            print(f"| 8-frame windows at stride {s} (`manifest` + `build --no-depth`, "
                  f"{secs:.1f} s) | {stored} | {data / 1e6:.2f} MB | "
                  f"{data / stored / 1e3:.1f} KB | {total / 1e6:.2f} MB | "
                  f"{total / ep_total:.2f}x |")
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
