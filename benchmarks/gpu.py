"""The GPU paths on one card: batched depth, and the paper-size models trained, predicted, scored.

Depth: a calibration of each mapping (lut, poly, mlp; the mlp trained on the GPU) fitted on
simulated sphere presses at 480x640; every mapping x solver reconstructs the same frames on the
numpy path of this machine's CPU and in torch on the GPU at several batch sizes (`reconstruct`
with `device="cuda"`, frames in and depth out through host memory, as a user calls it), in one
alternated run (each mode once per round; the median round), beside the gs_sdk-style reference
(benchmarks/gs_sdk_style.py, 2 threads); the largest difference between the GPU's depth and the
numpy path's says that both compute the same map.

Training: the v2-demo benchmark is made (`vtsbench benchmark v2-demo`), then each paper-size
model (TimeSformer-base 8x224x224 with the results profile's config, ResNet-50 at 224) trains for
--steps steps through its recipe on the GPU (mixed precision) four times, reading each batch in
the loop, then reading the next one ahead in a thread (TimeSformer's choice on CUDA) twice, then in
the loop again (each mode's figure the mean of its two runs), is predicted with
`vtsbench predict --device cuda` and scored with `vtsbench eval`. Per step: the median seconds,
and the share spent reading and cutting the batch on the CPU (`read_items`), hence the hours the
profile's 6,000 steps would take. The scores after so few steps say nothing of the models; the
run checks that the GPU path works end to end and measures its speed.

    python benchmarks/gpu.py [--out DIR] [--frames 32] [--rounds 3] [--steps 40]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from depth import alternated  # benchmarks/depth.py: one alternated timing run
from gs_sdk_style import GsSdkStyle  # benchmarks/gs_sdk_style.py: the reference pipeline
from machine import machine  # benchmarks/machine.py: the shared machine line
from results_matrix import PAPER_RESNET, PAPER_STEPS, PAPER_TSF

METHODS = ("lut", "poly", "mlp")
SOLVERS = ("dct", "dst", "masked")
BATCHES = (1, 8, 32)


def depth_table(tmp: Path, args: argparse.Namespace, dev: str) -> list[str]:
    """Markdown rows: every mapping x solver, numpy against torch on `dev` at each batch size."""
    import torch

    from vtsbench.depth.calibration import calibrate, load_presses
    from vtsbench.depth.reconstruct import reconstruct
    from vtsbench.sim.simulate import simulate

    sim = tmp / "presses"
    simulate(sim, seed=9090, n_static=0, n_sequences=0, n_presses=30, workers=args.workers,
             progress=False)
    presses, *_ = load_presses(sim)
    frames = np.stack([presses[i % len(presses)].image for i in range(args.frames)])
    cals = {m: calibrate(sim, method=m, holdout=6, seed=0, device=dev).calibration
            for m in METHODS}
    modes: dict[str, Callable[[np.ndarray], object]] = {
        "gs_sdk-style": lambda f: [ref.surface(x) for x in f]}
    diff: dict[tuple[str, str], float] = {}
    for m in METHODS:
        for s in SOLVERS:
            want = reconstruct(frames[:4], cals[m], solver=s)
            got = reconstruct(frames[:4], cals[m], solver=s, device=dev)
            diff[(m, s)] = float(np.abs(got - want).max())
            modes[f"{m} {s} numpy"] = lambda f, c=cals[m], s=s: reconstruct(f, c, solver=s)
            for b in BATCHES:
                modes[f"{m} {s} {b}"] = (lambda f, c=cals[m], s=s, b=b:
                                         reconstruct(f, c, solver=s, device=dev, batch=b))
    threads = torch.get_num_threads()
    ref = GsSdkStyle(cals["lut"].background, cals["lut"].mm_per_px[0], 2)  # sets 2 threads
    try:
        speed = alternated(modes, frames, args.rounds)
    finally:
        torch.set_num_threads(threads)  # the training part reads its batches with all of them
    base = speed["gs_sdk-style"]
    head = " | ".join(f"{dev} batch {b} (x ref)" for b in BATCHES)
    rows = [f"Depth at 480x640, {args.frames} frames a mode, {args.rounds} alternated rounds "
            f"(median); reference: gs_sdk-style {base:.1f} frames/s on 2 CPU threads\n",
            f"| mapping | solver | numpy, CPU (x ref) | {head} | max torch - numpy (mm) |",
            "|---|---|---:|" + "---:|" * len(BATCHES) + "---:|"]
    for m in METHODS:
        for s in SOLVERS:
            cells = [f"{speed[f'{m} {s} {b}']:.1f} ({speed[f'{m} {s} {b}'] / base:.1f}x)"
                     for b in BATCHES]
            cpu = speed[f"{m} {s} numpy"]
            rows.append(f"| {m} | {s} | {cpu:.1f} ({cpu / base:.1f}x) | {' | '.join(cells)} | "
                        f"{diff[(m, s)]:.1e} |")
    return rows


def timed_train(recipe: Any, dataset: Path, split: str, out: Path, config: dict[str, Any],
                dev: str, prefetch: bool) -> dict[str, float]:
    """Train through the recipe, timing each step (one `read_items` call starts each step) and
    the batch reading within it; `prefetch`: the training loop's, the next batch read in a
    thread while the step computes."""
    import vtsbench.training as training

    marks: list[tuple[float, float]] = []
    read = training.read_items

    def timed(data: Any, idx: Any) -> list[Any]:
        t0 = time.perf_counter()
        items = read(data, idx)
        marks.append((t0, time.perf_counter()))
        return items

    loop = training.train_loop
    training.read_items = timed
    # forced over the recipe's own choice; the recipe imports train_loop when it trains
    training.train_loop = lambda *a, **k: loop(*a, **{**k, "prefetch": prefetch})
    t0 = time.perf_counter()
    try:
        recipe.train(dataset, split, out, config, seed=0, device=dev, progress=False)
    finally:
        training.read_items, training.train_loop = read, loop
    total = time.perf_counter() - t0
    steps = np.diff([a for a, _ in marks])[3:]  # steps after the first three (warm-up)
    reads = np.array([b - a for a, b in marks])[3:-1]
    return {"total_s": total, "step_s": float(np.median(steps)),
            "read_s": float(np.median(reads))}


def cli(*argv: str) -> float:
    """Run a vtsbench command as a user would; its seconds."""
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "vtsbench.cli", *argv], check=True)
    return time.perf_counter() - t0


def training_table(tmp: Path, args: argparse.Namespace, dev: str) -> list[str]:
    """Markdown rows: each paper-size model's step time, reading share, projection, scores."""
    from vtsbench.recipes.config import load_config
    from vtsbench.recipes.registry import load_recipe

    bench = tmp / "v2demo"
    made = cli("benchmark", "v2-demo", str(bench), "--workers", str(args.workers), "--quiet")
    ds = bench / "dataset"
    runs = [("timesformer-base-rgb", "timesformer", "unseen_objects",
             {**PAPER_TSF, "crop_px": 200, "tta": dev != "cpu", "pretrained": False}),
            ("resnet50-rgb", "resnet", "static_sessions",
             {**PAPER_RESNET, "crop_px": 200, "modality": "rgb", "gradcam": 0})]
    rows = [f"v2-demo made in {made:.0f} s ({args.workers} workers); {args.steps} steps a "
            "model (the scores after so few steps say nothing of the model)\n",
            "| model | batch | s/step, batch read in the loop | reading it | s/step, next batch "
            "read ahead | 6,000 steps | predict, test part (s) | accuracy |",
            "|---|---:|---:|---:|---:|---:|---:|---|"]
    for name, recipe_name, split, config in runs:
        if recipe_name not in args.models.split(","):
            continue
        config = {**config, "steps": args.steps, "checkpoint_every": 10 ** 6, "threads": None,
                  **({"batch_size": args.batch} if args.batch else {})}
        out = tmp / "runs" / name
        recipe = load_recipe(recipe_name)
        given = tmp / f"{name}.json"  # checked against the recipe's defaults, as `train` does
        given.write_text(json.dumps(config))
        config = load_config(recipe, given)
        # in the loop, ahead, ahead, in the loop: an order effect (warm caches, clocks) hits both
        abba = [timed_train(recipe, ds, split, out / f"run{i}", config, dev, prefetch=p)
                for i, p in enumerate((False, True, True, False))]
        t = {k: (abba[0][k] + abba[3][k]) / 2 for k in abba[0]}
        ahead = {k: (abba[1][k] + abba[2][k]) / 2 for k in abba[1]}
        print(f"{name}: s/step in the loop {abba[0]['step_s']:.3f} {abba[3]['step_s']:.3f}, "
              f"ahead {abba[1]['step_s']:.3f} {abba[2]['step_s']:.3f}", flush=True)
        out = out / "run2"
        sub = tmp / f"{name}.csv"
        pred = cli("predict", recipe_name, str(out / "checkpoint.safetensors"), "--dataset",
                   str(ds), "--split", split, "--out", str(sub), "--device", dev)
        cli("eval", str(sub), "--dataset", str(ds), "--split", split,
            "--out", str(tmp / f"{name}-eval"))
        metrics = json.loads((tmp / f"{name}-eval" / "metrics.json").read_text())
        scores = ", ".join(f"{task} {v['summary']['accuracy']['mean']:.3f}"
                           for task, v in metrics["tasks"].items())
        hours = ahead["step_s"] * PAPER_STEPS["gpu"][recipe_name] / 3600
        rows.append(f"| {name} | {config['batch_size']} | {t['step_s']:.3f} | "
                    f"{t['read_s'] / t['step_s']:.0%} | {ahead['step_s']:.3f} "
                    f"({t['step_s'] / ahead['step_s']:.2f}x) | {hours:.1f} h | {pred:.0f} | "
                    f"{scores} |")
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, help="also write the tables to OUT/gpu.md")
    ap.add_argument("--frames", type=int, default=32, help="frames per mode and round")
    ap.add_argument("--rounds", type=int, default=3, help="alternated timing rounds")
    ap.add_argument("--steps", type=int, default=40, help="training steps per model")
    ap.add_argument("--workers", type=int, default=8)
    ap.add_argument("--batch", type=int, help="another batch size than the profile's")
    ap.add_argument("--device", default="cuda", help="cuda (cpu: a dry run of the script)")
    ap.add_argument("--parts", default="depth,training")
    ap.add_argument("--models", default="timesformer,resnet", help="recipes to train")
    args = ap.parse_args()
    text: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        for part, fn in (("depth", depth_table), ("training", training_table)):
            if part not in args.parts.split(","):
                continue
            t0 = time.perf_counter()
            try:
                rows = fn(Path(tmp), args, args.device)
            except Exception:  # one part's failure must not lose the other's figures
                rows = [f"{part}: failed\n```\n{traceback.format_exc()}```"]
            text += [*rows, f"\n({part}: {time.perf_counter() - t0:.0f} s)\n"]
            print("\n".join(text), flush=True)
            if args.out:
                args.out.mkdir(parents=True, exist_ok=True)
                (args.out / "gpu.md").write_text("\n".join(text) + f"\nMachine: {machine()}\n")
    print(f"\nMachine: {machine()}")


if __name__ == "__main__":
    main()
