"""Video storage of RGB frames against the Zarr store: bytes, speed and accuracy per codec.

Run: nice -n 15 .venv/bin/python benchmarks/codecs.py [--takes 6] [--sim-sequences 6]
     [--sim-frames 64] [--windows 40] [--gop N] [--codecs ffv1,h264,...] [--parts real,sim,recipe]
     [--dataset BUILT_V2_DEMO]

Sources: (a) real continuous takes, ../shared/data/real/incipient_slip_sample/<object>/exp_num_1/
camera_0.avi of the first --takes objects (320x240, 25 fps, MPEG-4: decoded once to RGB, and
those frames are the source); skipped with a message when the folder is absent. (b) simulated
sequences (`vtsbench simulate`, --sim-frames frames each, static, press and slip in turn) at
240x320 and 480x640. Each sequence is stored once per storage: Zarr as the build stores RGB
(zstd level 3, one chunk a frame, every frame of a take in one shard: build/store.py's encoder,
opened with zarr to read), and one video file per codec of format/video.py. Reported per
storage: bytes a frame, encode frames/s, sequential decode frames/s (a whole take), random
8-frame windows/s (--windows random starts a take, the file probed once), each with the
process's CPU time, and PSNR against the source (all frames; the worst take beside it).

(c) --parts recipe: the flow recipe on the v2-demo benchmark (`vtsbench benchmark v2-demo`,
or --dataset), trained and scored on unseen_objects as built, then on copies whose slip RGB
went through each codec (each 8-frame sequence encoded and decoded; depth and contact as
built, lossless); reports state and direction accuracy and how many test predictions match
the uncompressed run's. Everything is written in a temporary folder and removed.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from machine import machine  # benchmarks/machine.py: the shared machine line

from vtsbench.dataset.build.store import write_metadata, write_shard
from vtsbench.dataset.build.video import encode_frames
from vtsbench.dataset.format.arrays import Layout
from vtsbench.dataset.format.video import CODECS, VideoCodec
from vtsbench.dataset.read.video import decode_frames, probe

ROOT = Path(__file__).resolve().parent.parent
REAL = ROOT.parent / "shared" / "data" / "real" / "incipient_slip_sample"
VTSBENCH = str(Path(sys.executable).parent / "vtsbench")
WINDOW = 8
#: The simulated sensor's frame rate (docs/simulator.md); the real takes are 25 fps.
SIM_FPS = 30.0
ZSTD_LEVEL = 3


@dataclasses.dataclass
class Row:
    """One storage's figures on one set of takes."""

    storage: str
    settings: str
    frames: int = 0
    takes: int = 0
    raw_bytes: int = 0
    bytes: int = 0
    encode: list[float] = dataclasses.field(default_factory=lambda: [0.0, 0.0])  # wall, CPU
    decode: list[float] = dataclasses.field(default_factory=lambda: [0.0, 0.0])
    windows: list[float] = dataclasses.field(default_factory=lambda: [0.0, 0.0])
    n_windows: int = 0
    probe_s: float = 0.0
    sq_err: float = 0.0
    worst_psnr: float = float("inf")
    exact: bool = True


@dataclasses.dataclass
class Clock:
    """Wall and process CPU seconds of a block (CPU counts every thread: encoders use both
    cores)."""

    wall: float = 0.0
    cpu: float = 0.0

    def __enter__(self) -> Clock:
        self._w, self._c = time.perf_counter(), time.process_time()
        return self

    def __exit__(self, *exc: object) -> None:
        self.wall = time.perf_counter() - self._w
        self.cpu = time.process_time() - self._c


def psnr_of(mse: float) -> float:
    return float("inf") if mse == 0 else 10 * np.log10(255.0**2 / mse)


def mse_of(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.mean((a.astype(np.float32) - b.astype(np.float32)) ** 2))


# -- sources --------------------------------------------------------------------------------


def real_takes(n: int) -> list[np.ndarray] | None:
    """The first n objects' exp_num_1/camera_0.avi decoded to RGB, or None without the data."""
    import av

    if not REAL.is_dir():
        return None
    out = []
    for obj in sorted(p for p in REAL.iterdir() if p.is_dir())[:n]:
        with av.open(str(obj / "exp_num_1" / "camera_0.avi")) as c:
            out.append(np.stack([f.to_ndarray(format="rgb24") for f in c.decode(video=0)]))
    return out


def sim_takes(work: Path, size: str, sequences: int, frames: int) -> list[np.ndarray]:
    """Simulated sequences (`vtsbench simulate`), read back from their PNG frames."""
    from vtsbench.recordings.media import read_frames

    out_dir = work / f"sim-{size}"
    subprocess.run([VTSBENCH, "simulate", str(out_dir), "--seed", "0", "--static", "0",
                    "--sequences", str(sequences), "--presses", "0", "--size", size,
                    "--frames", str(frames), "--quiet"], check=True,
                   stdout=subprocess.DEVNULL)
    return [read_frames(p) for p in sorted((out_dir / "sequences").iterdir())]


# -- one storage ----------------------------------------------------------------------------


def windows_of(n: int, count: int, rng: np.random.Generator) -> list[int]:
    return rng.integers(0, n - WINDOW + 1, count).tolist()


def measure_zarr(takes: list[np.ndarray], work: Path, windows: int) -> Row:
    """Zarr as the build stores RGB: one zstd chunk a frame, a take in one shard file."""
    import zarr

    row = Row("Zarr", f"zstd level {ZSTD_LEVEL}, chunk = 1 frame")
    rng = np.random.default_rng(0)
    for k, take in enumerate(takes):
        n, h, w, _ = take.shape
        layout = Layout("static", n, (h, w), None, n, ZSTD_LEVEL, ("rgb",))
        group = work / f"zarr-{k}"
        with Clock() as c:
            write_metadata(group, layout)
            write_shard(group, layout, 0, {"rgb": take})
        _add(row.encode, c)
        row.bytes += sum(p.stat().st_size for p in group.rglob("*") if p.is_file())
        arr = zarr.open_array(group / "rgb", mode="r")
        with Clock() as c:
            back = arr[:]
        _add(row.decode, c)
        _score(row, take, back)
        starts = windows_of(n, windows, rng)
        with Clock() as c:
            for s in starts:
                arr[s:s + WINDOW]
        _add(row.windows, c)
        row.n_windows += len(starts)
        shutil.rmtree(group)
    return row


def measure_video(takes: list[np.ndarray], work: Path, codec: VideoCodec, windows: int,
                  fps: float) -> Row:
    """One video file a take, through encode_frames, probe and decode_frames."""
    row = Row(codec.name, codec.describe())
    rng = np.random.default_rng(0)
    for k, take in enumerate(takes):
        path = work / f"take-{k}{codec.suffix}"
        with Clock() as c:
            row.bytes += encode_frames(take, path, codec, fps)
        _add(row.encode, c)
        with Clock() as c:
            info = probe(path, expected_frames=len(take))
        row.probe_s += c.wall
        with Clock() as c:
            back = decode_frames(path, 0, len(take), info)
        _add(row.decode, c)
        _score(row, take, back)
        starts = windows_of(len(take), windows, rng)
        with Clock() as c:
            for s in starts:
                decode_frames(path, s, WINDOW, info)
        _add(row.windows, c)
        row.n_windows += len(starts)
        path.unlink()
    return row


def _add(acc: list[float], c: Clock) -> None:
    acc[0] += c.wall
    acc[1] += c.cpu


def _score(row: Row, take: np.ndarray, back: np.ndarray) -> None:
    row.frames += len(take)
    row.takes += 1
    row.raw_bytes += take.nbytes
    mse = mse_of(take, back)
    row.sq_err += mse * len(take)
    row.worst_psnr = min(row.worst_psnr, psnr_of(mse))
    row.exact &= bool(np.array_equal(take, back))


# -- tables ---------------------------------------------------------------------------------


def storage_table(title: str, rows: list[Row]) -> str:
    f = rows[0].frames
    head = (f"**{title}** ({f} frames; raw RGB {rows[0].raw_bytes / f / 1e3:.1f} kB a frame)\n\n"
            "| storage | bytes/frame | vs raw | encode frames/s (CPU ms/frame) | sequential "
            "decode frames/s (CPU ms/frame) | random 8-frame windows/s (CPU ms/window) | "
            "probe ms/take | PSNR dB (worst take) | bit-exact |\n"
            "|---|---:|---:|---:|---:|---:|---:|---:|---|\n")
    lines = []
    for r in rows:
        psnr = psnr_of(r.sq_err / r.frames)
        shown = "inf" if psnr == float("inf") else f"{psnr:.2f} ({r.worst_psnr:.2f})"
        lines.append(
            f"| {r.storage} | {r.bytes / r.frames:,.0f} | {r.raw_bytes / r.bytes:.1f}x | "
            f"{r.frames / r.encode[0]:.0f} ({1e3 * r.encode[1] / r.frames:.2f}) | "
            f"{r.frames / r.decode[0]:.0f} ({1e3 * r.decode[1] / r.frames:.2f}) | "
            f"{r.n_windows / r.windows[0]:.0f} ({1e3 * r.windows[1] / r.n_windows:.2f}) | "
            f"{_probe_ms(r)} | {shown} | {'yes' if r.exact else 'no'} |")
    return head + "\n".join(lines) + "\n"


def _probe_ms(r: Row) -> str:
    return "-" if r.storage == "Zarr" else f"{1e3 * r.probe_s / r.takes:.1f}"


def settings_table(codecs: list[VideoCodec]) -> str:
    lines = [f"| {c.name} | {c.describe()} |" for c in codecs]
    return "| storage | settings |\n|---|---|\n| Zarr | zstd level 3 (+crc32c), one chunk " \
           "a frame |\n" + "\n".join(lines) + "\n"


# -- recipe accuracy ------------------------------------------------------------------------


def run_cli(*args: str) -> None:
    subprocess.run([VTSBENCH, *args], check=True, stdout=subprocess.DEVNULL)


def flow_scores(ds: Path, out: Path) -> dict[str, Any]:
    """Train, predict and evaluate flow on unseen_objects; accuracies and the predictions."""
    run_cli("train", "flow", "--dataset", str(ds), "--split", "unseen_objects", "--out",
            str(out / "run"), "--device", "cpu", "--quiet")
    run_cli("predict", "flow", str(out / "run" / "checkpoint.safetensors"), "--dataset",
            str(ds), "--split", "unseen_objects", "--out", str(out / "pred.csv"),
            "--device", "cpu")
    run_cli("eval", str(out / "pred.csv"), "--dataset", str(ds), "--split", "unseen_objects",
            "--out", str(out / "eval"), "--no-figures")
    doc = json.loads((out / "eval" / "metrics.json").read_text())
    with open(out / "pred.csv", newline="") as fh:
        preds = {(r["sample_id"], r["task"]): r["pred"] for r in csv.DictReader(fh)}
    runs = {t: doc["tasks"][t]["runs"][0] for t in ("state", "direction")}
    return {"runs": runs, "preds": preds, "scored": scored_keys(ds)}


def scored_keys(ds: Path) -> list[tuple[str, str]]:
    """(sample, task) of the test part that eval scores: state for every sample, direction
    for the slipping ones."""
    import vtsbench

    test = vtsbench.load(ds).split("unseen_objects", "test")
    states = test.index["state"].to_pylist()
    return [(i, "state") for i in test.ids] + [
        (i, "direction") for i, s in zip(test.ids, states, strict=True) if s == "slip"]


def transcode_copy(ds: Path, copy: Path, codec: VideoCodec, work: Path) -> dict[str, float]:
    """A copy of the dataset whose slip RGB went through the codec (info.json's checksums
    renewed); returns the video bytes and the PSNR of the slip RGB."""
    import zarr

    from vtsbench.atomic import write_text_atomic
    from vtsbench.dataset.format.info import dataset_checksum, load_info
    from vtsbench.dataset.format.layout import INFO_PATH, group_path

    shutil.copytree(ds, copy)
    info = load_info(copy / INFO_PATH)
    n, frames, h, w, _ = info.shapes["slip"]["rgb"]
    layout = Layout("slip", n, (h, w), frames, info.zarr.samples_per_shard["slip"],
                    info.zarr.level, ("rgb",))
    arr = zarr.open_array(ds / group_path("slip") / "rgb", mode="r")
    video_bytes, sq_err = 0, 0.0
    tmp = work / f"seq{codec.suffix}"
    for k in range(layout.n_shards):
        rows = layout.shard_rows(k)
        block = arr[rows.start:rows.stop]
        out = np.empty_like(block)
        for i, seq in enumerate(block):
            video_bytes += encode_frames(seq, tmp, codec, SIM_FPS)
            out[i] = decode_frames(tmp, 0, len(seq))
            sq_err += mse_of(seq, out[i])
        digests: dict[str, str] = {}
        write_shard(copy / group_path("slip"), layout, k, {"rgb": out}, digests)
        info.files[f"{group_path('slip')}/{layout.shard_key('rgb', k)}"] = digests["rgb"]
    tmp.unlink(missing_ok=True)
    info.dataset_sha256 = dataset_checksum(info.files)
    write_text_atomic(copy / INFO_PATH, info.to_json())
    return {"video_bytes": video_bytes, "psnr": psnr_of(sq_err / n)}


def zarr_slip_rgb_bytes(ds: Path) -> int:
    from vtsbench.dataset.format.layout import group_path

    return sum(p.stat().st_size for p in (ds / group_path("slip") / "rgb").rglob("*")
               if p.is_file())


def recipe_part(work: Path, dataset: Path | None, codecs: list[VideoCodec]) -> str:
    if dataset is None:
        t = time.perf_counter()
        run_cli("benchmark", "v2-demo", str(work / "v2demo"), "--workers", "1", "--quiet")
        print(f"v2-demo made in {time.perf_counter() - t:.0f} s", file=sys.stderr)
        dataset = work / "v2demo" / "dataset"
    base = flow_scores(dataset, work / "base")
    n_seq = json.loads((dataset / "meta" / "info.json").read_text())["shapes"]["slip"]["rgb"][0]
    rows = [_recipe_row("Zarr (as built, lossless)", zarr_slip_rgb_bytes(dataset), n_seq,
                        float("inf"), base, base)]
    for codec in codecs:
        t = time.perf_counter()
        copy = work / f"ds-{codec.name}"
        figures = transcode_copy(dataset, copy, codec, work)
        scores = flow_scores(copy, work / f"flow-{codec.name}")
        rows.append(_recipe_row(codec.name, figures["video_bytes"], n_seq, figures["psnr"],
                                scores, base))
        shutil.rmtree(copy)
        print(f"{codec.name}: {time.perf_counter() - t:.0f} s", file=sys.stderr)
    return ("| slip RGB stored as | kB per 8-frame sequence | PSNR dB | state accuracy % | "
            "direction accuracy % [95 % CI] | same state as uncompressed % | same direction "
            "as uncompressed % (slipping samples) |\n|---|---:|---:|---:|---:|---:|---:|\n"
            + "\n".join(rows) + "\n")


def _recipe_row(name: str, nbytes: int, n_seq: int, psnr: float, scores: dict[str, Any],
                base: dict[str, Any]) -> str:
    st, di = scores["runs"]["state"], scores["runs"]["direction"]
    same = {}
    for task in ("state", "direction"):
        keys = [k for k in base["scored"] if k[1] == task]
        same[task] = 100 * np.mean([scores["preds"][k] == base["preds"][k] for k in keys])
    ci = di["accuracy_ci95"]
    shown = "inf" if psnr == float("inf") else f"{psnr:.2f}"
    return (f"| {name} | {nbytes / n_seq / 1e3:.1f} | {shown} | {100 * st['accuracy']:.1f} "
            f"(n {st['n']}) | {100 * di['accuracy']:.1f} [{100 * ci[0]:.1f}, {100 * ci[1]:.1f}]"
            f" (n {di['n']}) | {same['state']:.1f} | {same['direction']:.1f} |")


# -- main -----------------------------------------------------------------------------------


def storage_part(title: str, takes: list[np.ndarray], work: Path, codecs: list[VideoCodec],
                 windows: int, fps: float) -> str:
    rows = [measure_zarr(takes, work, windows)]
    for codec in codecs:
        rows.append(measure_video(takes, work, codec, windows, fps))
        print(f"{title}: {codec.name} done", file=sys.stderr)
    return storage_table(title, rows)


def chosen_codecs(names: str, gop: int | None) -> list[VideoCodec]:
    out = [CODECS[n] for n in names.split(",")]
    if gop is not None:
        out = [c if c.lossless else dataclasses.replace(c, name=f"{c.name}-g{gop}", gop=gop)
               for c in out]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", default="real,sim,recipe")
    ap.add_argument("--codecs", default=",".join(CODECS))
    ap.add_argument("--gop", type=int, default=None, help="keyframe interval of lossy codecs")
    ap.add_argument("--takes", type=int, default=6)
    ap.add_argument("--sim-sequences", type=int, default=6)
    ap.add_argument("--sim-frames", type=int, default=64)
    ap.add_argument("--sizes", default="240x320,480x640")
    ap.add_argument("--windows", type=int, default=40, help="random windows a take")
    ap.add_argument("--dataset", type=Path, default=None, help="a built v2-demo dataset")
    args = ap.parse_args()
    parts = set(args.parts.split(","))
    codecs = chosen_codecs(args.codecs, args.gop)
    start = time.perf_counter()
    out = [settings_table(codecs)]
    with tempfile.TemporaryDirectory(prefix="vts-codecs-") as tmp:
        work = Path(tmp)
        if "real" in parts:
            takes = real_takes(args.takes)
            if takes is None:
                out.append(f"real takes skipped: {REAL} is absent\n")
            else:
                out.append(storage_part(f"Real takes: {len(takes)} of incipient_slip_sample, "
                                        "320x240", takes, work, codecs, args.windows, 25.0))
        if "sim" in parts:
            for size in args.sizes.split(","):
                takes = sim_takes(work, size, args.sim_sequences, args.sim_frames)
                out.append(storage_part(f"Simulated: {len(takes)} sequences of "
                                        f"{args.sim_frames} frames, {size}", takes, work,
                                        codecs, args.windows, SIM_FPS))
        if "recipe" in parts:
            out.append(recipe_part(work, args.dataset, codecs))
    print("\n".join(out))
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    print(f"Machine: {machine()}; {time.perf_counter() - start:.0f} s wall, "
          f"{time.process_time() + ru.ru_utime + ru.ru_stime:.0f} s CPU (this process and "
          f"the commands it ran)")


if __name__ == "__main__":
    os.environ.setdefault("SVT_LOG", "1")
    main()
