"""Live slip monitoring (`vtsbench stream`): frames per second sustained and p50/p95 latency of
each built-in recipe on a 25 fps stream at 240x320 and 480x640, against the recipe's batch
predict per sample in the same run; the flow recipe's speed/accuracy trade-off; then a real
GelSight Mini take streamed end to end.

Per resolution: a small simulated dataset (12 slip sequences of 8 frames, 12 static frames,
RGB only), the flow tree fitted on it, a TimeSformer (the demo's small config) and a
ResNet-18 (the demo's) trained briefly on it, 1 torch thread each. The stream: the dataset's
slip frames one after the other, played at 25 fps (`realtime`: frames the model is too slow
for are dropped and counted) for --frames frames.

The flow configs (FLOW_CONFIGS: the DIS flow's `scale` and `preset`, the global shift's
`shift_scale`): each trained on the train part of unseen_objects of a simulated RGB-only
dataset at 480x640 (what a stream gives: no contact masks; generator 2, 900 sequences,
0.03 mm/px, seed 26) and scored on its test part (state accuracy; direction accuracy on the
slipping sequences, the state given; Wilson 95 % intervals; against the default config, the
samples one gets right and the other wrong), and each streamed at both sizes: realtime (wall
ms, dropped) and as fast as it goes (CPU ms a call: process time, both OpenCV threads, less
moved by other jobs than wall time). --compare FILE (a copy of an earlier flow.py) streams
that file's flow at the default config too, alternating with the current one.

Then `vtsbench stream flow` on incipient_slip_sample/blue_mug/exp_num_1/camera_0.avi (--take)
with the tree fitted at 240x320, writing its JSON lines and an annotated video under --out.

    .venv/bin/python benchmarks/stream.py [--frames 125] [--steps 20] [--out /tmp/vts-stream]
        [--compare /tmp/flow_before.py] [--only-flow]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT))

from live import play, warm_up  # noqa: E402
from machine import machine  # noqa: E402
from results_matrix import DEMO_RESNET, DEMO_TSF  # noqa: E402

TAKE = ROOT.parent / "shared/data/real/incipient_slip_sample/blue_mug/exp_num_1/camera_0.avi"
SIZES = ((240, 320), (480, 640))
FPS = 25.0
#: The flow configs of the trade-off table (keys over the recipe's default config).
FLOW_CONFIGS = (
    ("default (scale 1, shift 1)", {}),
    ("scale 1, shift 0.5", {"shift_scale": 0.5}),
    ("scale 0.5, shift 0.5", {"scale": 0.5, "shift_scale": 0.5}),
    ("scale 0.5, shift 0.5, ultrafast", {"scale": 0.5, "shift_scale": 0.5,
                                         "preset": "ultrafast"}),
    ("scale 0.25, shift 0.5", {"scale": 0.25, "shift_scale": 0.5}),
)
#: The accuracy dataset: generator 2 at 480x640 (0.03 mm/px: the 240x320 benchmark's gel).
ACCURACY_SEQUENCES, ACCURACY_SEED = 900, 26


def simulated(rec: Path, ds: Path, **sim: Any) -> Path:
    """ds: recordings simulated into rec with sim (no presses) built RGB-only; kept if there."""
    from vtsbench.dataset.build import BuildOptions, build
    from vtsbench.sim.simulate import simulate

    if not ds.exists():
        simulate(rec, n_presses=0, progress=False, **sim)
        build(rec, ds, BuildOptions(depth=False))
    return ds


def dataset(root: Path, size: tuple[int, int]) -> Path:
    """A small simulated RGB-only dataset at size."""
    return simulated(root / f"rec-{size[0]}", root / f"ds-{size[0]}", seed=7, n_static=12,
                     n_sequences=12, size=size, mm_per_px=0.06 * 240 / size[0])


def accuracy_dataset(root: Path) -> Path:
    """The simulated RGB-only 480x640 dataset the flow configs are scored on."""
    return simulated(root / "acc-rec-480", root / "acc-ds-480", seed=ACCURACY_SEED,
                     n_static=30, n_sequences=ACCURACY_SEQUENCES, size=(480, 640),
                     mm_per_px=0.03)


def wilson(k: int, n: int) -> tuple[float, float]:
    """Wilson 95 % interval of k successes in n, in %."""
    if n == 0:
        return float("nan"), float("nan")
    z, p = 1.96, k / n
    c = (p + z * z / (2 * n)) / (1 + z * z / n)
    h = z * ((p * (1 - p) / n + z * z / (4 * n * n)) ** 0.5) / (1 + z * z / n)
    return 100 * (c - h), 100 * (c + h)


def flow_accuracy(ds: Path, out: Path, config: dict) -> dict:
    """Train flow with config on unseen_objects/train, predict its test part: per-sample
    hits of state and of direction (slipping sequences), and the seconds each took."""
    import vtsbench
    from vtsbench.labels import STATES

    view = vtsbench.load(ds).split("unseen_objects", "test")
    truth_state = dict(zip(view.ids, view.index["state_idx"].to_pylist(), strict=True))
    truth_dir = dict(zip(view.ids, view.index["direction"].to_pylist(), strict=True))
    t0 = time.perf_counter()
    ckpt = train("flow", ds, out, config, "unseen_objects")
    t1 = time.perf_counter()
    from vtsbench.recipes import load_recipe

    rec = load_recipe("flow")
    rows = rec.predict(ckpt, ds, "unseen_objects", "test")
    state = {r["sample_id"]: r["pred"] == STATES[truth_state[r["sample_id"]]]
             for r in rows if r["task"] == "state" and truth_state[r["sample_id"]] is not None}
    direction = {r["sample_id"]: r["pred"] == truth_dir[r["sample_id"]]
                 for r in rows if r["task"] == "direction" and truth_dir[r["sample_id"]]
                 is not None}
    return {"state": state, "direction": direction, "train_s": round(t1 - t0, 1),
            "predict_ms_median": round(1000 * statistics.median(rec.latency_s), 1)}


def cpu_per_call(recipe: str, ckpt: Path, frames) -> dict:
    """The monitor on the frames as fast as it goes: CPU ms (process time) and wall ms of
    each call, p50 and p95."""
    import numpy as np

    from vtsbench.recipes.monitor import Monitor

    monitor = Monitor.from_checkpoint(recipe, ckpt, device="cpu")
    for f in frames[:monitor.frames]:
        monitor.push(f)
    monitor.reset()
    cpu, wall = [], []
    for f in frames:
        c0, t0 = time.process_time(), time.perf_counter()
        call = monitor.push(f)
        t1, c1 = time.perf_counter(), time.process_time()
        if call is not None:
            cpu.append(1000 * (c1 - c0))
            wall.append(1000 * (t1 - t0))
    return {"cpu_ms_p50": round(float(np.percentile(cpu, 50)), 1),
            "cpu_ms_p95": round(float(np.percentile(cpu, 95)), 1),
            "wall_ms_p50": round(float(np.percentile(wall, 50)), 1),
            "wall_ms_p95": round(float(np.percentile(wall, 95)), 1)}


def load() -> str:
    return "load average " + " ".join(f"{v:.1f}" for v in os.getloadavg())


def flow_table(args: argparse.Namespace, streams: dict) -> None:
    """The flow configs' accuracy at 480x640 and their monitor's speed at both sizes."""
    ds = accuracy_dataset(args.out)
    acc = {}
    for name, cfg in FLOW_CONFIGS:
        acc[name] = flow_accuracy(ds, args.out / f"acc-flow-{slug(name)}", cfg)
        a = acc[name]
        print(json.dumps({"config": name, "state_n": len(a["state"]),
                          "state_ok": sum(a["state"].values()),
                          "direction_n": len(a["direction"]),
                          "direction_ok": sum(a["direction"].values()),
                          "train_s": a["train_s"], "predict_ms_median": a["predict_ms_median"],
                          "load": load()}), flush=True)
    speed: dict = {}
    versions = [("current", "flow")] + ([("previous", str(args.compare))] if args.compare
                                         else [])
    for size in SIZES:
        ds_size, frames = streams[size]
        for round_ in range(args.rounds):
            for name, cfg in FLOW_CONFIGS:
                ckpt = train("flow", ds_size, args.out / f"flow-{size[0]}-{slug(name)}", cfg,
                             "unseen_objects")
                for version, recipe in versions if not cfg else versions[:1]:
                    s = live_stream(recipe, ckpt, frames)
                    c = cpu_per_call(recipe, ckpt, frames)
                    row = {"config": name, "version": version, "size": f"{size[0]}x{size[1]}",
                           "round": round_, **{k: s[k] for k in (
                               "dropped", "frames", "fps_sustained", "latency_ms_p50",
                               "latency_ms_p95")}, **c, "load": load()}
                    speed.setdefault((name, version, size), []).append(row)
                    print(json.dumps(row), flush=True)
    print()
    print("| flow config | state % [95 % interval] | direction % [95 % interval] | vs default: "
          "state right/wrong flips, direction | stream | frames/s (of 25) | dropped | "
          "wall p50 / p95 | CPU ms p50 / p95 |")
    print("|---|---|---|---|---|---:|---:|---|---|")
    base = acc[FLOW_CONFIGS[0][0]]
    for name, _ in FLOW_CONFIGS:
        a = acc[name]
        cells = []
        for task in ("state", "direction"):
            k, n = sum(a[task].values()), len(a[task])
            lo, hi = wilson(k, n)
            cells.append(f"{100 * k / n:.1f} [{lo:.1f}, {hi:.1f}] (n {n})")
        flips = ", ".join(
            f"+{sum(a[t][i] and not base[t][i] for i in a[t])}/"
            f"-{sum(base[t][i] and not a[t][i] for i in a[t])}" for t in ("state", "direction"))
        for version in ("current", "previous"):
            for size in SIZES:
                rows = speed.get((name, version, size))
                if not rows:
                    continue
                label = name if version == "current" else f"{name}, previous flow.py"
                acc_cells = " | ".join(cells) + f" | {flips}" if version == "current" else \
                    "same | same | -"
                print(f"| {label} | {acc_cells} | {size[0]}x{size[1]} | "
                      f"{min(r['fps_sustained'] for r in rows):.1f} | "
                      f"{max(r['dropped'] for r in rows)} of {rows[0]['frames']} | "
                      f"{max(r['latency_ms_p50'] for r in rows):.1f} / "
                      f"{max(r['latency_ms_p95'] for r in rows):.1f} ms | "
                      f"{max(r['cpu_ms_p50'] for r in rows):.1f} / "
                      f"{max(r['cpu_ms_p95'] for r in rows):.1f} ms |")
    print("(speed cells: the worst of the rounds)")


def slug(name: str) -> str:
    return "".join(c if c.isalnum() else "-" for c in name).strip("-")


def configs(steps: int) -> dict[str, tuple[dict, str]]:
    """Each recipe's config and the split it trains and predicts on."""
    return {"flow": ({}, "unseen_objects"),
            "timesformer": ({**DEMO_TSF, "flow_mask": None, "steps": steps,
                             "checkpoint_every": steps, "threads": 1}, "unseen_objects"),
            "resnet": ({**DEMO_RESNET, "modality": "rgb", "steps": steps,
                        "checkpoint_every": steps, "gradcam": 0, "threads": 1},
                       "static_sessions")}


def train(recipe: str, ds: Path, out: Path, config: dict, split: str) -> Path:
    """The recipe's checkpoint in out, trained with config over its default (kept if there)."""
    from vtsbench.recipes import load_recipe

    rec = load_recipe(recipe)
    ckpt = out / ("checkpoint.safetensors")
    if ckpt.exists():
        return ckpt
    return rec.train(ds, split, out, {**rec.default_config(), **config}, progress=False)


def batch_predict(recipe: str, ckpt: Path, ds: Path, split: str) -> tuple[float, float, int]:
    """ms per sample of the recipe's predict over the split's test part (wall, and its own
    median latency), and the samples."""
    from vtsbench.recipes import load_recipe

    rec = load_recipe(recipe)
    t0 = time.perf_counter()
    rows = rec.predict(ckpt, ds, split, "test")
    wall = time.perf_counter() - t0
    n = len({r["sample_id"] for r in rows})
    return 1000 * wall / n, 1000 * statistics.median(rec.latency_s), n


def stream_frames(ds: Path, n: int):
    """n frames: the dataset's slip sequences one after the other, repeated."""
    import numpy as np

    import vtsbench

    view = vtsbench.load(ds).view("slip")
    clip = np.concatenate([view[i]["rgb"] for i in range(len(view))])
    return clip[np.arange(n) % len(clip)]


def live_stream(recipe: str, ckpt: Path, frames) -> dict:
    """The monitor on the frames played at FPS (realtime: drops counted; benchmarks/live.py)."""
    from vtsbench.recipes.monitor import Monitor

    monitor = Monitor.from_checkpoint(recipe, ckpt, device="cpu")
    warm_up(monitor, frames)
    return play(monitor, frames, FPS, "bench")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=125)
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--out", type=Path, default=Path("/tmp/vts-stream"))
    ap.add_argument("--compare", type=Path, default=None)
    ap.add_argument("--only-flow", action="store_true")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    import torch

    torch.set_num_threads(1)
    print(f"start: {load()}", flush=True)
    rows = []
    ckpts = {}
    streams = {}
    for size in SIZES:
        ds = dataset(args.out, size)
        frames = stream_frames(ds, args.frames)
        streams[size] = ds, frames
        for recipe, (config, split) in configs(args.steps).items():
            if args.only_flow:
                break
            t0 = time.perf_counter()
            ckpt = train(recipe, ds, args.out / f"{recipe}-{size[0]}", config, split)
            train_s = time.perf_counter() - t0
            ckpts[(recipe, size)] = ckpt
            s = live_stream(recipe, ckpt, frames)
            c = cpu_per_call(recipe, ckpt, frames)
            per_sample, own, n = batch_predict(recipe, ckpt, ds, split)
            row = {"recipe": recipe, "size": f"{size[0]}x{size[1]}", "train_s": round(train_s, 1),
                   **{k: s[k] for k in ("frames", "processed", "dropped", "calls",
                                        "fps_sustained", "latency_ms_p50",
                                        "latency_ms_p95")}, **c,
                   "predict_ms_per_sample": round(per_sample, 2),
                   "predict_latency_ms_median": round(own, 2), "predict_samples": n,
                   "ratio_p50_to_predict": round(s["latency_ms_p50"] / per_sample, 2),
                   "load": load()}
            rows.append(row)
            print(json.dumps(row), flush=True)
    if rows:
        print()
        print("| recipe | stream | frames/s sustained (of 25) | dropped | latency p50 | p95 | "
              "CPU ms p50 / p95 | batch predict per sample | p50 / predict |")
        print("|---|---|---:|---:|---:|---:|---|---:|---:|")
    for r in rows:
        print(f"| {r['recipe']} | {r['size']} | {r['fps_sustained']:.1f} | "
              f"{r['dropped']} of {r['frames']} | {r['latency_ms_p50']:.1f} ms | "
              f"{r['latency_ms_p95']:.1f} ms | {r['cpu_ms_p50']:.1f} / {r['cpu_ms_p95']:.1f} ms | "
              f"{r['predict_ms_per_sample']:.1f} ms "
              f"({r['predict_samples']} samples) | {r['ratio_p50_to_predict']:.2f}x |")
    print()
    flow_table(args, streams)
    if TAKE.is_file() and ("flow", (240, 320)) in ckpts:
        lines, video = args.out / "camera_0.jsonl", args.out / "camera_0-calls.mp4"
        t0 = time.perf_counter()
        with open(lines, "wb") as fh:
            res = subprocess.run([str(ROOT / ".venv/bin/vtsbench"), "stream", "flow",
                                  str(ckpts[("flow", (240, 320))]), "--source", str(TAKE),
                                  "--video-out", str(video)], stdout=fh, stderr=subprocess.PIPE,
                                 text=True, check=False)
        docs = [json.loads(x) for x in lines.read_text().splitlines()]
        states = [d["state"] for d in docs if d["type"] == "call"]
        print(f"\nreal take {TAKE.name}: exit {res.returncode}, {time.perf_counter() - t0:.1f} s; "
              f"{res.stderr.strip()}; states: "
              f"{ {s: states.count(s) for s in sorted(set(states))} }; first slip call at frame "
              f"{next((d['frame_index'] for d in docs if d.get('state') == 'slip'), None)}; "
              f"{lines} ({len(docs)} lines), {video} ({video.stat().st_size} bytes); "
              f"summary {docs[-1]}")
    print(f"\nmachine: {machine()}; end: {load()}")


if __name__ == "__main__":
    main()
