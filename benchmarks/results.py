"""Speed against accuracy of the reference recipes: train, predict, score, enter the leaderboards
and write the results page (docs/results.md).

Run: .venv/bin/python benchmarks/results.py --dataset demo-data/dataset --runs demo-data/runs \
        [--leaderboards leaderboards] [--out docs/results.md] [--octopi DATASET] [--profile demo]

Every step goes through the `vtsbench` command, as a user would run it (`train`, `predict`,
`eval --out`, `leaderboard add`), so the page is also an end-to-end check of the commands:

- slip (`unseen_objects` and `seen`): the optical-flow baseline on frames resized to a quarter
  (`flow-quarter`, the fast one) and at full resolution (`flow-full`), and the small dual-head
  TimeSformer (RGB);
- static (`static_sessions`): ResNet-18 at 112x112 on RGB and on depth (the paper's ResNet-50 at
  224 is trained the same way with `{"arch": "resnet50", "image_size": 224}`; on a CPU it costs
  about 15x more);
- the paper-size models (TimeSformer-base 8x224x224, ResNet-50 224), not trained here: their
  parameters and CPU latency with random weights (latency does not depend on the weights);
- with `--octopi DATASET` (a static build of real GelSight Mini videos, held-out takes in
  `static_sessions`): ResNet-18 RGB on it.

A run whose checkpoint exists is not trained again (`vtsbench train` resumes: finished runs
cost nothing); `--retrain` starts them afresh. Latency is the median forward pass (flow: flow,
features and tree) per sample with a batch of one, as `vtsbench predict` measures it, on this
machine's CPU (and GPU when there is one). Prints the table and writes the page.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from machine import machine  # noqa: E402
from slip_effects import effect_table, slip_truth, submission_hits, wilson  # noqa: E402

#: The paper's figures (accuracy %), its own recordings and splits: a reference, not an entry.
PAPER = {
    ("slip", "seen"): {"state": 99.68, "direction": 96.95},
    ("slip", "unseen_objects"): {"state": 95.5, "direction": 91.5},
    ("static", "rgb"): {"object": 98.80},
    ("static", "depth"): {"object": 96.06},
}


@dataclass
class Run:
    """One recipe configuration trained on one split and scored on its test part."""

    method: str           # leaderboard name: recipe-size-modality
    recipe: str
    split: str
    config: dict[str, Any] = field(default_factory=dict)
    dataset: str = "synthetic"   # which dataset (key of the --dataset/--octopi paths)


#: The demo profile's configs (CPU, 2 cores, the whole `make demo` under 15 minutes), sized for
#: the benchmark's sensor (240x320 at 0.06 mm/px): a 128 px crop is 7.7 mm of gel around the
#: contact. The motion channels are the crop's dense DIS flow (`flow: dis`) kept where the gel
#: is in contact (`flow_mask: contact`): on generator-2 slips the whole-crop `shift` locks onto
#: the gel's fixed pattern like any registration, and the still gel dilutes a dense flow.
DEMO_TSF = {"config": "small", "modality": "rgb", "image_size": 64, "crop_px": 128,
            "input": "delta+flow", "flow": "dis", "flow_mask": "contact", "pool": "cls+mean",
            "steps": 300, "batch_size": 8,
            "checkpoint_every": 100, "fit_parts": ["train", "val"]}
DEMO_RESNET = {"arch": "resnet18", "image_size": 128, "crop_px": 160, "steps": 300,
               "batch_size": 16, "checkpoint_every": 100, "gradcam": 4,
               "fit_parts": ["train", "val"]}
#: Steps per modality in the demo: depth (one channel, no colour) needs twice RGB's to pass 85 %
#: (docs/models.md, "Which knob buys how much").
DEMO_RESNET_STEPS = {"rgb": 300, "depth": 600}
#: The v2 profile: the published benchmark (`vtsbench benchmark v2`: 3,600 sequences, 3,000
#: static frames) with the demo's model sizes trained longer, on 2 CPU cores.
V2_STEPS = {"timesformer": 1500, "resnet": {"rgb": 600, "depth": 1200}}
#: The results profile (paper scale: ~8,000 sequences, ~19,000 static frames, paper-size
#: models): steps on a GPU, and the fewer steps it falls back to on a CPU (the page says so).
PAPER_TSF = {"config": "paper", "modality": "rgb", "crop_px": 256,
             "input": "delta+flow", "flow": "shift", "flow_soft_px": 0.5, "pool": "cls+mean",
             "batch_size": 16,
             "lr": 1e-4, "warmup_steps": 200, "checkpoint_every": 500, "threads": None}
PAPER_RESNET = {"arch": "resnet50", "image_size": 224, "crop_px": 320, "batch_size": 32,
                "checkpoint_every": 500, "gradcam": 8, "threads": None}
PAPER_STEPS = {"gpu": {"timesformer": 6000, "resnet": 6000},
               "cpu": {"timesformer": 300, "resnet": 600}}
#: TimeSformer-base batch: 16 on a GPU; on a CPU 4, since one training run at 16 (8 frames at
#: 224) passed 23.7 GB and was killed for memory on a 24 GiB machine.
PAPER_TSF_BATCH = {"gpu": 16, "cpu": 4}


def profile_runs(profile: str, octopi: bool, *, gpu: bool = False,
                 pretrained: str | None = None) -> list[Run]:
    """The runs of a profile: `demo` (CPU-sized models on the demo's dataset, about 8 minutes
    on 2 CPU cores) or `results` (the paper's models, TimeSformer-base at 224 and ResNet-50,
    meant for a paper-scale dataset on a GPU; on a CPU with PAPER_STEPS["cpu"] steps).
    `pretrained`: folder of the SSv2 TimeSformer weights (results profile; without it the
    paper-size TimeSformer starts from random weights, and the page says so)."""
    runs = []
    if profile == "v2":
        tsf = {**DEMO_TSF, "steps": V2_STEPS["timesformer"], "checkpoint_every": 250}
        for split in ("unseen_objects", "seen"):
            runs.append(Run("flow-contact", "flow", split, {"scale": 0.25}))
            runs.append(Run("timesformer-small-rgb", "timesformer", split, dict(tsf)))
        runs.append(Run("timesformer-small-depth", "timesformer", "unseen_objects",
                        {**tsf, "modality": "depth"}))
        for mod in ("rgb", "depth"):
            runs.append(Run(f"resnet18-{mod}", "resnet", "static_sessions",
                            {**DEMO_RESNET, "modality": mod,
                             "steps": V2_STEPS["resnet"][mod], "checkpoint_every": 200}))
    elif profile == "demo":
        for split in ("unseen_objects", "seen"):
            runs.append(Run("flow-contact", "flow", split, {"scale": 0.25}))
            runs.append(Run("timesformer-small-rgb", "timesformer", split, dict(DEMO_TSF)))
        for mod in ("rgb", "depth"):
            runs.append(Run(f"resnet18-{mod}", "resnet", "static_sessions",
                            {**DEMO_RESNET, "modality": mod, "steps": DEMO_RESNET_STEPS[mod]}))
    else:
        where = "gpu" if gpu else "cpu"
        steps = PAPER_STEPS[where]
        tsf = {**PAPER_TSF, "steps": steps["timesformer"], "pretrained_path": pretrained,
               "batch_size": PAPER_TSF_BATCH[where],
               # the 8-view test-time average costs 25 s a sequence on a 2-core CPU (3 without)
               "tta": gpu,
               "pretrained": pretrained is not None}
        for split in ("unseen_objects", "seen"):
            runs.append(Run("flow-contact", "flow", split, {"scale": 0.25}))
            runs.append(Run("timesformer-base-rgb", "timesformer", split, dict(tsf)))
        runs.append(Run("timesformer-base-depth", "timesformer", "seen",
                        {**tsf, "modality": "depth"}))
        for mod in ("rgb", "depth"):
            runs.append(Run(f"resnet50-{mod}", "resnet", "static_sessions",
                            {**PAPER_RESNET, "modality": mod, "steps": steps["resnet"]}))
    if octopi:
        runs.append(Run("resnet18-rgb", "resnet", "static_sessions",
                        {**DEMO_RESNET, "modality": "rgb", "crop_px": None, "image_size": 112,
                         "steps": 800, "gradcam": 8}, dataset="octopi"))
    return runs


def expected_cost(run: Run) -> float:
    """Rough training seconds of a run, to start the long ones first: steps times the seconds
    of one demo-size step (measured side by side on 2 cores: ResNet-18 at 128 px, batch 16,
    0.7 s; small TimeSformer at 64 px, batch 8, 0.5 s); the flow recipe fits a tree in seconds."""
    per_step = {"resnet": 0.7, "timesformer": 0.5}.get(run.recipe, 0.0)
    return per_step * run.config.get("steps", 0)


def run_cli(*args: str, log: list[str]) -> float:
    """Run one `vtsbench` command (echoed, and kept for the page); its wall time in seconds."""
    exe = Path(sys.executable).with_name("vtsbench")
    cmd = [str(exe) if exe.exists() else "vtsbench", *args]
    shown = "vtsbench " + " ".join(args)
    print(f"$ {shown}", flush=True)
    log.append(shown)
    t0 = time.perf_counter()
    res = subprocess.run(cmd, text=True, capture_output=True)
    if res.returncode != 0:
        sys.exit(f"failed ({res.returncode}): {shown}\n{res.stdout}{res.stderr}")
    return time.perf_counter() - t0


def run_one(run: Run, ds: Path, runs_dir: Path, boards: Path, retrain: bool,
            log: list[str]) -> dict[str, Any]:
    """Train, predict, eval and leaderboard-add one run; its figures."""
    name = f"{run.dataset}-{run.method}-{run.split}"
    out = runs_dir / name
    cfg = out / "config-override.json"
    text = json.dumps(run.config, indent=1) + "\n"
    stale = cfg.exists() and cfg.read_text() != text  # trained with another config
    if (retrain or stale) and out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True, exist_ok=True)
    cfg.write_text(text)
    train_args = ["train", run.recipe, "--dataset", str(ds), "--split", run.split,
                  "--out", str(out), "--quiet"]
    if run.config:
        train_args += ["--config", str(cfg)]
    trained = not (out / "checkpoint.safetensors").exists()  # a finished run is not trained again
    if trained:
        train_s = run_cli(*train_args, log=log)
        (out / "train_seconds.txt").write_text(f"{train_s:.1f}\n")
    sub = runs_dir / f"{name}.csv"
    ckpt = out / "checkpoint.safetensors"
    scored = runs_dir / f"{name}.eval" / "metrics.json"
    # a submission newer than its checkpoint, scored after it was written, is reused: a rerun
    # that only adds a table costs no prediction
    if not (sub.exists() and sub.with_suffix(".meta.json").exists() and scored.exists()
            and ckpt.stat().st_mtime < sub.stat().st_mtime <= scored.stat().st_mtime):
        run_cli("predict", run.recipe, str(ckpt), "--dataset", str(ds),
                "--split", run.split, "--out", str(sub), "--method", run.method, log=log)
        run_cli("eval", str(sub), "--dataset", str(ds), "--split", run.split,
                "--out", str(runs_dir / f"{name}.eval"), log=log)
    meta = json.loads(sub.with_suffix(".meta.json").read_text())
    metrics = json.loads((runs_dir / f"{name}.eval" / "metrics.json").read_text())
    # one entry per method, split and dataset version: a re-run replaces the method's earlier
    # entry on the same version; entries on an earlier version stay (listed apart)
    board = boards / metrics["dataset"]["name"] / run.split
    version = metrics["dataset"]["dataset_version"]
    for old in board.glob(f"{run.method}-*.json"):
        if json.loads(old.read_text())["dataset"]["dataset_version"] == version:
            old.unlink()
    run_cli("leaderboard", "add", str(sub), "--dataset", str(ds), "--split", run.split,
             "--root", str(boards), "--overwrite", log=log)
    tasks = metrics["tasks"]

    def acc(task: str, key: str = "accuracy") -> float | None:
        if task not in tasks:
            return None
        v = tasks[task]["runs"][0].get(key)
        return None if v is None else 100.0 * v

    seconds = out / "train_seconds.txt"
    d0 = tasks["direction"]["runs"][0] if "direction" in tasks else {}
    s0 = tasks["state"]["runs"][0] if "state" in tasks else {}
    return {
        "adjacent": None if d0.get("adjacent_error_share") is None
        else 100.0 * d0["adjacent_error_share"],
        "by_magnitude": d0.get("by_magnitude"), "per_state": s0.get("per_state"),
        "environment": meta.get("environment"),
        "run": run, "name": name, "n": metrics["n_samples"], "trained": trained,
        "train_s": float(seconds.read_text()) if seconds.exists() else None,
        "latency_ms": meta.get("latency_ms_per_sample_median"),
        "state": acc("state"), "direction": acc("direction", "state_given_accuracy"),
        "direction_e2e": acc("direction", "end_to_end_accuracy"),
        "within_one": acc("direction", "within_one_bin"),
        "angular": (tasks["direction"]["runs"][0]["mean_abs_angular_error_deg"]
                    if "direction" in tasks else None),
        "n_dir": tasks["direction"]["runs"][0]["n"] if "direction" in tasks else None,
        "object": acc("object"), "dataset_name": metrics["dataset"]["name"],
        "dataset_sha": metrics["dataset"]["dataset_sha256"],
        "checkpoint": str(out / "checkpoint.safetensors"), "submission": str(sub),
        "direction_ci": _ci(tasks, "direction"),
    }


def _ci(tasks: dict[str, Any], task: str) -> list[float] | None:
    """The 95 % interval (%) of a task's accuracy (state given for direction), or None."""
    ci = tasks.get(task, {}).get("runs", [{}])[0].get("accuracy_ci95")
    return None if ci is None else [100.0 * ci[0], 100.0 * ci[1]]


def phase_reference(dataset: Path, split: str) -> dict[str, Any]:
    """The simplest method that should work: phase correlation of the first and the last frame
    (whole frame, full resolution, grey, no training) on the slipping test sequences; its
    direction accuracy, accuracy per slip distance and median time per sequence."""
    import math

    import cv2
    import numpy as np

    import vtsbench
    from vtsbench.evaluation.magnitude import by_magnitude, distances, slip_motion
    from vtsbench.labels import angle_to_class

    view = vtsbench.load(dataset).split(split, "test")
    ok, ids, times = [], [], []
    for s in view:
        if s["state"] != "slip" or s["direction"] is None:
            continue
        t0 = time.perf_counter()
        a, b = (cv2.cvtColor(np.ascontiguousarray(f), cv2.COLOR_RGB2GRAY).astype(np.float32)
                for f in (s["rgb"][0], s["rgb"][-1]))
        (dx, dy), _ = cv2.phaseCorrelate(a, b)
        pred = angle_to_class(math.degrees(math.atan2(-dy, dx)) % 360.0)
        times.append(time.perf_counter() - t0)
        ok.append(pred == s["direction"])
        ids.append(s["sample_id"])
    mm, px = distances(slip_motion(dataset, ids))
    ci = wilson(int(sum(ok)), len(ok))
    return {"split": split, "n_dir": len(ok),
            "direction": 100.0 * float(np.mean(ok)) if ok else None,
            "direction_ci": None if ci is None else [100.0 * ci[0], 100.0 * ci[1]],
            "hits": dict(zip(ids, map(bool, ok), strict=True)),
            "latency_ms": 1000 * statistics.median(times) if times else None,
            "by_magnitude": by_magnitude(ok, mm, px)}


def parameters(run: Run, n_objects: int) -> int:
    """Trainable parameters of a run's model (flow: the fitted tree's nodes)."""
    import torch

    if run.recipe == "timesformer":
        from vtsbench.models.timesformer import DualHeadTimesformer

        with torch.device("meta"):
            m = DualHeadTimesformer.from_config(
                run.config.get("config", "small"), run.config.get("modality", "rgb"),
                pretrained=False, image_size=run.config.get("image_size"),
                with_delta=run.config.get("input") in (None, "frames+delta"))
        return sum(p.numel() for p in m.parameters())
    if run.recipe == "resnet":
        from vtsbench.models.resnet import static_resnet

        with torch.device("meta"):
            m = static_resnet(n_objects, run.config.get("modality", "rgb"),
                              arch=run.config.get("arch", "resnet50"))
        return sum(p.numel() for p in m.parameters())
    return 0


def tree_nodes(checkpoint: str) -> int:
    from safetensors.numpy import load_file

    arrays = load_file(checkpoint)
    return len(next(iter(arrays.values())))


def paper_size_latency(device: str, repeats: int) -> list[dict[str, Any]]:
    """Parameters and forward latency (batch of one, random weights) of the paper's models."""
    import torch

    from vtsbench.models.resnet import static_resnet
    from vtsbench.models.timesformer import DualHeadTimesformer

    out = []
    dev = torch.device(device)
    models = [
        ("timesformer-base (paper)", "slip",
         lambda: DualHeadTimesformer.from_config("paper", "rgb", pretrained=False),
         (1, 8, 3, 224, 224)),
        ("resnet50 (paper)", "static", lambda: static_resnet(15, "rgb", arch="resnet50"),
         (1, 3, 224, 224)),
    ]
    for name, kind, make, shape in models:
        torch.manual_seed(0)
        model = make().to(dev).eval()
        x = torch.rand(shape, device=dev)
        times = []
        with torch.inference_mode():
            model(x)  # warm-up
            for _ in range(repeats):
                if dev.type == "cuda":
                    torch.cuda.synchronize()
                t0 = time.perf_counter()
                model(x)
                if dev.type == "cuda":
                    torch.cuda.synchronize()
                times.append(time.perf_counter() - t0)
        out.append({"name": name, "kind": kind, "device": device,
                    "params": sum(p.numel() for p in model.parameters()),
                    "latency_ms": 1000 * statistics.median(times), "repeats": repeats})
        del model
    return out


def _pct(v: float | None) -> str:
    return "-" if v is None else f"{v:.1f}"


def _ms(v: float | None) -> str:
    if v is None:
        return "-"
    return f"{v:.1f}" if v < 100 else f"{v:.0f}"


def _m(n: int) -> str:
    return f"{n / 1e6:.1f} M" if n >= 1e5 else f"{n:,}"


def render(rows: list[dict[str, Any]], paper_rows: list[dict[str, Any]], info: dict[str, Any],
           commands: list[str], elapsed: float) -> str:
    """The results page (markdown)."""
    slip = [r for r in rows if r["run"].recipe in ("flow", "timesformer")]
    static = [r for r in rows if r["run"].recipe == "resnet"]
    kept = sum(not r.get("trained", True) for r in rows)
    reused = (f" ({kept} of {len(rows)} runs trained earlier and reused: their training time "
              "is the train s column)") if kept else ""
    lines = [
        "# Results: speed against accuracy",
        "",
        "Generated by `benchmarks/results.py` (do not edit by hand); re-run it to refresh:",
        "",
        "```bash",
        f".venv/bin/python benchmarks/results.py --dataset {info['dataset']} "
        f"--runs {info['runs']} --profile {info['profile']}"
        + (f" --octopi {info['octopi']}" if info.get("octopi") else ""),
        "```",
        "",
        f"Machine: {info['machine']}. Devices: {info['devices']}. "
        f"Whole run {elapsed / 60:.1f} min{reused}. {info.get('steps_note', '')}",
        "",
        f"Synthetic benchmark: `{info['dataset_name']}` built from `vtsbench simulate` "
        f"({info['dataset_desc']}), dataset_sha256 `{info['dataset_sha'][:16]}...`. "
        "Accuracy on the split's `test` part, one seed; latency per sample with a batch of one "
        "(median; reading excluded; flow: flow, features and tree; TimeSformer: crop, motion "
        "channels and forward pass; ResNet: forward pass). "
        "The paper's figures are on its own real recordings (83,000 RGB-D frames, "
        "ImageNet/SSv2-pretrained models), so they are a reference row, not a comparable entry.",
        "",
        "## Slip: state and direction",
        "",
        "| method | split | device | params | latency ms | train s | state % | direction % "
        "(state given) | 95 % interval | direction % end to end | within one bin % | adjacent "
        "share of errors % | angular error deg | test n (slipping) |",
        "|---|---|---|---:|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|",
    ]
    for r in slip:
        params = f"{r['params']} tree nodes" if r["run"].recipe == "flow" else _m(r["params"])
        lines.append(
            f"| {r['run'].method} | {r['run'].split} | {r.get('device', 'cpu')} | {params} | "
            f"{_ms(r['latency_ms'])} | {_ms(r['train_s'])} | {_pct(r['state'])} | "
            f"{_pct(r['direction'])} | {_interval(r.get('direction_ci'))} | "
            f"{_pct(r['direction_e2e'])} | {_pct(r['within_one'])} | "
            f"{_pct(r.get('adjacent'))} | "
            f"{'-' if r['angular'] is None else round(r['angular'])} | "
            f"{r['n']} ({r['n_dir']}) |")
    for ref in info.get("references", []):
        lines.append(f"| phase correlation, first and last frame (reference) | {ref['split']} | "
                     f"cpu | none | {_ms(ref['latency_ms'])} | - | - | "
                     f"{_pct(ref['direction'])} | {_interval(ref.get('direction_ci'))} | - | - "
                     f"| - | - | - ({ref['n_dir']}) |")
    for p in paper_rows:
        if p["kind"] == "slip":
            for split in ("seen", "unseen_objects"):
                ref = PAPER[("slip", split)]
                lines.append(f"| {p['name']} | {split} (paper's data) | {p['device']} | "
                             f"{_m(p['params'])} | {_ms(p['latency_ms'])} | - | {ref['state']} | "
                             f"{ref['direction']} | - | - | - | mostly adjacent | - | - |")
    lines += magnitude_tables(slip, info.get("references", []))
    lines += effect_tables(slip, info.get("references", []), info.get("effects", {}))
    lines += state_table(slip)
    lines += ["", "## Static: object recognition", "",
              "| method | dataset / split | classes | params | CPU latency ms | train s | "
              "object % | test n |", "|---|---|---:|---:|---:|---:|---:|---:|"]
    for r in static:
        where = f"{r['dataset_name']} / {r['run'].split}"
        lines.append(f"| {r['run'].method} | {where} | {r['classes']} | {_m(r['params'])} | "
                     f"{_ms(r['latency_ms'])} | {_ms(r['train_s'])} | {_pct(r['object'])} | "
                     f"{r['n']} |")
    for p in paper_rows:
        if p["kind"] == "static":
            for mod in ("rgb", "depth"):
                lines.append(f"| {p['name']}, {mod} | paper's data | 15 | {_m(p['params'])} | "
                             f"{_ms(p['latency_ms'])} | - | {PAPER[('static', mod)]['object']} "
                             "| - |")
    lines += other_table(info.get("other"))
    lines += ["", "## What the figures say", ""] + info["findings"] + [
        "", "## Where the figures are", "",
        f"- per run: `{info['runs']}/<dataset>-<method>-<split>/` (checkpoint, config), "
        "`.csv` + `.meta.json` (submission), `.eval/` (metrics.json, report.md, confusion "
        "PNGs); Grad-CAM overlays in the ResNet runs' `gradcam/`;",
        f"- leaderboards: `{info['leaderboards']}/<dataset>/<split>/leaderboard.md`;",
        "- the configs: " + "; ".join(
            f"{r['run'].method} `{json.dumps(r['run'].config)}`" for r in rows
            if r["run"].config and r["run"].split != "seen" and r["run"].dataset == "synthetic")
        + ".",
        "", "Commands run:", "", "```bash"] + commands + ["```", ""]
    return "\n".join(lines)


def _interval(ci: list[float] | None) -> str:
    return "-" if ci is None else f"[{ci[0]:.1f}, {ci[1]:.1f}]"


def effect_tables(slip: list[dict[str, Any]], refs: list[dict[str, Any]],
                  truths: dict[str, dict[str, Any]]) -> list[str]:
    """Per split: direction accuracy (state given) by what the simulator did to the sequence,
    for every slip run and the phase-correlation reference (95 % Wilson intervals)."""
    out: list[str] = []
    for split, truth in truths.items():
        runs = [r for r in slip if r["run"].split == split and r.get("submission")]
        ref = next((x for x in refs if x["split"] == split), None)
        if not runs or not truth:
            continue
        cols = [(f"{r['run'].method} %", submission_hits(Path(r["submission"]), truth))
                for r in runs]
        if ref and ref.get("hits"):
            cols.append(("phase correlation reference %", ref["hits"]))
        out += ["", f"Direction by effect, {split} (state given; slipping test sequences; "
                "accuracy % [95 % Wilson interval]; the effects are the simulator's own record "
                "of each sequence in the index):", "", *effect_table(truth, cols)]
    return out


def magnitude_tables(slip: list[dict[str, Any]], refs: list[dict[str, Any]]) -> list[str]:
    """Per split: direction accuracy (state given) per slip-distance bin for every slip run and
    the reference, with each run's pixels at its input (bin median)."""
    out: list[str] = []
    for split in ("unseen_objects", "seen"):
        runs = [r for r in slip if r["run"].split == split and r.get("by_magnitude")]
        ref = next((x for x in refs if x["split"] == split), None)
        if not runs:
            continue
        head = ["slip distance mm", "n"] + [f"{r['run'].method} % (px at its input)"
                                           for r in runs]
        if ref:
            head.append("phase correlation reference % (px on the sensor)")
        out += ["", f"Direction by slip distance, {split} (state given; bins from the index's "
                "motion; pixels: the bin's median at the method's input):", "",
                "| " + " | ".join(head) + " |", "|---|---:" + "|---:" * (len(head) - 2) + "|"]
        cols = [r["by_magnitude"]["bins"] for r in runs] + \
            ([ref["by_magnitude"]["bins"]] if ref else [])
        for i, b in enumerate(cols[0]):
            hi = "inf" if b["hi_mm"] is None else f"{b['hi_mm']:g}"
            cells = [f"[{b['lo_mm']:g}, {hi})", str(b["n"])]
            for c in cols:
                x = c[i]
                cells.append("-" if x["accuracy"] is None else
                             f"{100 * x['accuracy']:.1f} ({x['px_median']:.1f})")
            out.append("| " + " | ".join(cells) + " |")
    return out


def other_table(other: dict[str, Any] | None) -> list[str]:
    """The same profile's figures on another dataset (its --summary JSON)."""
    if not other:
        return []
    refs = {r["split"]: r for r in other.get("references", [])}
    out = ["", f"## The same recipes on another simulated dataset ({other.get('label', '')}"
           f"dataset_sha256 `{other['dataset_sha256'][:16]}...`, same counts)", "",
           "| method | split | state % | direction % (state given) | adjacent share of errors "
           "% | object % | phase correlation reference direction % |",
           "|---|---|---:|---:|---:|---:|---:|"]
    for r in other["rows"]:
        ref = refs.get(r["split"])
        out.append(f"| {r['method']} | {r['split']} | {_pct(r.get('state'))} | "
                   f"{_pct(r.get('direction'))} | {_pct(r.get('adjacent'))} | "
                   f"{_pct(r.get('object'))} | {_pct(ref['direction']) if ref else '-'} |")
    return out


def state_table(slip: list[dict[str, Any]]) -> list[str]:
    """State accuracy per true state of every slip run."""
    runs = [r for r in slip if r.get("per_state")]
    if not runs:
        return []
    names = list(runs[0]["per_state"])
    out = ["", "State accuracy per true state (test part):", "",
           "| method | split | " + " | ".join(f"{n} % (n)" for n in names) + " |",
           "|---|---" + "|---:" * len(names) + "|"]
    for r in runs:
        cells = [f"{_pct(None if v['accuracy'] is None else 100 * v['accuracy'])} ({v['n']})"
                 for v in r["per_state"].values()]
        out.append(f"| {r['run'].method} | {r['run'].split} | " + " | ".join(cells) + " |")
    return out


def findings(rows: list[dict[str, Any]], paper: list[dict[str, Any]],
             refs: list[dict[str, Any]] | None = None) -> list[str]:
    """Sentences comparing each recipe with the phase-correlation reference and the paper."""
    out = []
    refs = refs or []
    for split in ("unseen_objects", "seen"):
        ref = next((x for x in refs if x["split"] == split), None)
        p = PAPER[("slip", split)]
        for r in rows:
            if r["run"].split != split or r["direction"] is None:
                continue
            text = (f"- {split}, {r['run'].method}: direction {r['direction']:.1f} % with the "
                    f"state given ({r['n_dir']} slipping test sequences; chance 12.5 %)")
            if r.get("direction_ci"):
                text += f" [95 % interval {r['direction_ci'][0]:.1f}-{r['direction_ci'][1]:.1f}]"
            if ref and ref["direction"] is not None:
                gap = r["direction"] - ref["direction"]
                text += (f", {abs(gap):.1f} points {'above' if gap >= 0 else 'below'} the phase "
                         f"correlation of the first and last frame ({ref['direction']:.1f} %")
                if r.get("direction_ci") and ref.get("direction_ci"):
                    apart = (r["direction_ci"][0] > ref["direction_ci"][1]
                             or r["direction_ci"][1] < ref["direction_ci"][0])
                    text += (f" [{ref['direction_ci'][0]:.1f}-{ref['direction_ci'][1]:.1f}]; the "
                             f"intervals {'do not overlap' if apart else 'overlap'}")
                text += ")"
            text += f"; the paper's TimeSformer {p['direction']} % on its own data"
            if r["state"] is not None:
                text += f". State {r['state']:.1f} % (paper {p['state']} %)"
            if r.get("adjacent") is not None:
                text += f"; {r['adjacent']:.0f} % of the direction errors on the adjacent bin"
            elif r["direction"] == 100.0:
                text += "; no direction error"
            out.append(text + ".")
    for split in ("unseen_objects", "seen"):
        by_mod = {r["run"].config.get("modality", "rgb"): r for r in rows
                  if r["run"].recipe == "timesformer" and r["run"].split == split
                  and r["direction"] is not None}
        if "rgb" in by_mod and "depth" in by_mod:
            rgb, dep = by_mod["rgb"], by_mod["depth"]
            word = "above" if rgb["direction"] > dep["direction"] else "not above"
            out.append(f"- {split}: TimeSformer on RGB {rgb['direction']:.1f} % direction, "
                       f"{word} the same model on depth alone ({dep['direction']:.1f} %); state "
                       f"{_pct(rgb['state'])} against {_pct(dep['state'])} %. The paper's pattern "
                       "is RGB above depth-only.")
    flows = [r for r in rows if r["run"].recipe == "flow" and r["latency_ms"]]
    tsfs = [r for r in rows if r["run"].recipe == "timesformer" and r["latency_ms"]]
    if flows and tsfs:
        f, t = flows[0], tsfs[0]
        out.append(f"- Speed: the classical baseline takes {f['latency_ms']:.1f} ms a sequence, "
                   f"the {t['run'].method} {t['latency_ms']:.1f} ms "
                   f"({t['latency_ms'] / f['latency_ms']:.1f}x).")
    for p in paper:
        if p["kind"] == "slip" and p["device"] == "cpu" and flows:
            fast = min(r["latency_ms"] for r in flows)
            out.append(f"- Against the paper-size TimeSformer-base on this CPU "
                       f"({p['latency_ms']:.0f} ms a sequence), the flow baseline is "
                       f"{p['latency_ms'] / fast:.0f}x faster ({fast:.1f} ms).")
    for r in rows:
        if r["run"].recipe == "resnet" and r["object"] is not None:
            mod = r["run"].config.get("modality", "rgb")
            ref = PAPER.get(("static", mod), {}).get("object")
            parts = "+".join(r["run"].config.get("fit_parts") or ["train"])
            out.append(f"- {r['run'].method} on {r['dataset_name']} / {r['run'].split}: "
                       f"{r['object']:.1f} % over {r['classes']} classes (chance "
                       f"{100 / r['classes']:.1f} %), trained from random weights on "
                       f"{r['n_train']} frames ({parts})"
                       + (f"; the paper's ResNet-50 {ref} % on its "
                                                   "own data" if ref else "") + ".")
    return out or ["- (no runs)"]


def no_gpu() -> bool:
    """True when no CUDA device is visible (checked without importing torch)."""
    import shutil

    return not (os.environ.get("CUDA_VISIBLE_DEVICES", "x") != "" and
                (shutil.which("nvidia-smi") or Path("/dev/nvidia0").exists()))


def steps_note(profile: str, gpu: bool, pretrained: str | None) -> str:
    """What the page must say about the compute its figures had."""
    if profile == "v2":
        return ("v2 profile: the published benchmark (`vtsbench benchmark v2`), models of the "
                "demo's size trained longer on 2 CPU cores "
                f"({V2_STEPS['timesformer']} TimeSformer steps, ResNet "
                f"{V2_STEPS['resnet']['rgb']} on RGB and {V2_STEPS['resnet']['depth']} on depth); "
                "the paper-scale results profile (`make results`) was not run for this page.")
    if profile == "demo":
        return ("Demo profile: CPU-sized models and steps (what `make demo` trains on 2 CPU "
                "cores); the paper-scale results profile (`make results`) was not run for this "
                "page.")
    cpu, gpu_ = PAPER_STEPS["cpu"], PAPER_STEPS["gpu"]
    where = "on a GPU" if gpu else (
        f"on the CPU, with fewer steps than on a GPU ({cpu['timesformer']} TimeSformer and "
        f"{cpu['resnet']} ResNet steps against {gpu_['timesformer']} and {gpu_['resnet']}) "
        f"and a TimeSformer batch of {PAPER_TSF_BATCH['cpu']} against "
        f"{PAPER_TSF_BATCH['gpu']} (memory), no test-time averaging (8x the latency): the "
        "paper-size models are under-trained here")
    init = "from the SSv2 weights" if pretrained else "from random weights (no SSv2 weights given)"
    return f"Results profile: paper-size models trained {where}; TimeSformer-base {init}."


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dataset", type=Path, required=True, help="synthetic dataset folder")
    ap.add_argument("--runs", type=Path, required=True, help="folder for runs and submissions")
    ap.add_argument("--leaderboards", type=Path, default=ROOT / "leaderboards")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results.md")
    ap.add_argument("--octopi", type=Path, default=None,
                    help="static RGB build of real videos (held-out takes in static_sessions)")
    ap.add_argument("--profile", choices=("demo", "v2", "results"), default="demo")
    ap.add_argument("--splits", default=None,
                    help="comma-separated splits to run (default: all of the profile's), e.g. "
                         "unseen_objects for a check on a dataset of another seed")
    ap.add_argument("--retrain", action="store_true", help="train every run afresh")
    ap.add_argument("--repeats", type=int, default=5, help="forward passes timed per paper model")
    ap.add_argument("--jobs", type=int, default=None,
                    help="runs trained side by side (default: 2 for the demo profile on a "
                         "CPU-only machine, else 1: two paper-size TimeSformers training side by "
                         "side on the CPU were killed for memory on a 24 GiB machine)")
    ap.add_argument("--pretrained", default=None,
                    help="results profile: folder of the SSv2 TimeSformer weights")
    ap.add_argument("--other", type=Path, default=None,
                    help="summary JSON (--summary) of the same profile on another dataset, "
                         "e.g. simulated with another seed: shown in its own table")
    ap.add_argument("--steps", type=int, default=None,
                    help="train every model run for this many steps instead of the profile's "
                         "(a smoke run of the whole path; the page says so)")
    ap.add_argument("--summary", type=Path, default=None,
                    help="also write the rows as JSON here (accuracies, devices, versions)")
    args = ap.parse_args()

    import torch

    import vtsbench
    from vtsbench.recipes import fit_view

    t0 = time.perf_counter()
    paths = {"synthetic": args.dataset, "octopi": args.octopi}
    log: list[str] = []
    rows = []
    gpu = torch.cuda.is_available()
    device = "cuda" if gpu else "cpu"
    runs = profile_runs(args.profile, args.octopi is not None, gpu=gpu,
                        pretrained=args.pretrained)
    if args.splits:
        keep = set(args.splits.split(","))
        runs = [r for r in runs if r.split in keep]
    if args.steps is not None:  # a smoke run: every trained run with this many steps
        runs = [Run(r.method, r.recipe, r.split, {**r.config, "steps": args.steps}
                    if "steps" in r.config else r.config, r.dataset) for r in runs]
    logs: list[list[str]] = [[] for _ in runs]
    # independent runs side by side, one torch thread each (the recipes pin it): on 2 cores
    # two single-threaded runs beat one two-threaded run, whose OpenMP threads stall when the
    # machine is busy; each run's figures do not depend on what runs beside it
    # longest first, so that the last run to start is a short one and neither worker idles
    # while the other trains a long run alone
    order = sorted(range(len(runs)), key=lambda k: -expected_cost(runs[k]))
    jobs = args.jobs or (2 if args.profile in ("demo", "v2") and no_gpu() else 1)
    with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
        started = list(pool.map(lambda k: run_one(runs[k], paths[runs[k].dataset], args.runs,
                                                  args.leaderboards, args.retrain, logs[k]),
                                order))
    done = [started[order.index(k)] for k in range(len(runs))]
    for run, r, run_log in zip(runs, done, logs, strict=True):
        log += run_log
        ds = paths[run.dataset]
        n_obj = len(vtsbench.load(ds).info.objects)
        r["params"] = tree_nodes(r["checkpoint"]) if run.recipe == "flow" else \
            parameters(run, n_obj)
        r["classes"] = n_obj
        train = fit_view(ds, run.split, run.config.get("fit_parts") or ["train"])
        r["n_train"] = len(train)
        if "state" in train.index.column_names:
            r["n_slip_train"] = train.index["state"].to_pylist().count("slip")
        r["device"] = device if run.recipe != "flow" else "cpu"
        rows.append(r)
    splits = [sp for sp in ("unseen_objects", "seen") if any(r.split == sp for r in runs)]
    refs = [phase_reference(args.dataset, split) for split in splits]
    effects = {sp: slip_truth(args.dataset, sp) for sp in splits} if args.profile == "v2" else {}
    run_cli("leaderboard", "render", "--root", str(args.leaderboards), log=log)
    devices = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
    paper_rows = []
    for dev in devices:
        paper_rows += paper_size_latency(dev, args.repeats)
    paper_rows = [p for p in paper_rows if p["device"] == "cpu"] + \
        [dict(p, name=f"{p['name']} on GPU") for p in paper_rows if p["device"] != "cpu"]
    info_ds = vtsbench.load(args.dataset)
    h, w = info_ds.info.resolution
    counts = (f"{len(info_ds.static)} static frames and {len(info_ds.slip)} sequences of "
              f"{info_ds.info.frames_per_sequence} frames at {h}x{w}")
    info = {
        "dataset": os.path.relpath(args.dataset, ROOT), "runs": os.path.relpath(args.runs, ROOT),
        "octopi": None if args.octopi is None else os.path.relpath(args.octopi, ROOT),
        "leaderboards": os.path.relpath(args.leaderboards, ROOT), "profile": args.profile,
        "machine": machine(), "devices": ", ".join(
            [f"CPU ({torch.get_num_threads()} torch threads)"]
            + ([torch.cuda.get_device_name(0)] if torch.cuda.is_available() else
               ["no GPU on this machine"])),
        "dataset_name": rows[0]["dataset_name"], "dataset_sha": rows[0]["dataset_sha"],
        "dataset_desc": counts, "findings": findings(rows, paper_rows, refs),
        "references": refs, "effects": effects,
        "steps_note": steps_note(args.profile, gpu, args.pretrained)
        + ("" if args.steps is None else f" Smoke run: every model trained for only "
           f"{args.steps} steps (--steps), so its figures say nothing of the recipe."),
        "other": None if args.other is None else json.loads(args.other.read_text()),
    }
    elapsed = time.perf_counter() - t0
    page = render(rows, paper_rows, info, log, elapsed)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(page)
    print()
    print("## Slip" + page.split("## What the figures say")[0].split("## Slip", 1)[1])
    print("\n".join(info["findings"]))
    if args.summary is not None:
        args.summary.write_text(json.dumps(
            {"dataset_sha256": info["dataset_sha"], "profile": args.profile,
             "label": f"{info['dataset_desc']}; ",
             "elapsed_s": round(elapsed, 1),
             "references": [{k: v for k, v in r.items() if k != "hits"} for r in refs],
             "rows": [{k: v for k, v in r.items() if k not in ("run", "checkpoint")}
                      | {"method": r["run"].method, "split": r["run"].split}
                      for r in rows]}, indent=1, default=str) + "\n")
    print(f"\nresults page: {args.out}; leaderboards: {args.leaderboards}; runs: {args.runs}")


if __name__ == "__main__":
    main()
