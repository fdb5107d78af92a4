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
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from machine import machine  # noqa: E402

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


def profile_runs(profile: str, octopi: bool) -> list[Run]:
    """The runs of a profile: `demo` (the demo's, about 9 minutes on 2 CPU cores) or `results`
    (the demo's runs, reused when trained, plus the flow baseline at full resolution)."""
    tsf = {"config": "small", "modality": "rgb", "steps": 250, "batch_size": 8,
           "slip_oversample": 3, "checkpoint_every": 50}
    res = {"arch": "resnet18", "image_size": 112, "steps": 150, "batch_size": 16,
           "checkpoint_every": 50, "gradcam": 4}
    runs = []
    for split in ("unseen_objects", "seen"):
        runs.append(Run("flow-quarter", "flow", split, {"scale": 0.25}))
        if profile == "results":
            runs.append(Run("flow-full", "flow", split, {"scale": 1.0}))
        runs.append(Run("timesformer-small-rgb", "timesformer", split, dict(tsf)))
    runs.append(Run("resnet18-rgb", "resnet", "static_sessions", {**res, "modality": "rgb"}))
    runs.append(Run("resnet18-depth", "resnet", "static_sessions", {**res, "modality": "depth"}))
    if octopi:
        runs.append(Run("resnet18-rgb", "resnet", "static_sessions",
                        {**res, "modality": "rgb", "steps": 800, "gradcam": 8},
                        dataset="octopi"))
    return runs


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
    done = (out / "checkpoint.safetensors").exists()
    train_s = run_cli(*train_args, log=log)
    if not done:
        (out / "train_seconds.txt").write_text(f"{train_s:.1f}\n")
    sub = runs_dir / f"{name}.csv"
    run_cli("predict", run.recipe, str(out / "checkpoint.safetensors"), "--dataset", str(ds),
             "--split", run.split, "--out", str(sub), "--method", run.method, log=log)
    run_cli("eval", str(sub), "--dataset", str(ds), "--split", run.split,
             "--out", str(runs_dir / f"{name}.eval"), log=log)
    meta = json.loads(sub.with_suffix(".meta.json").read_text())
    metrics = json.loads((runs_dir / f"{name}.eval" / "metrics.json").read_text())
    # one entry per method and split: a re-run replaces the method's earlier entry
    board = boards / metrics["dataset"]["name"] / run.split
    for old in board.glob(f"{run.method}-*.json"):
        old.unlink()
    run_cli("leaderboard", "add", str(sub), "--dataset", str(ds), "--split", run.split,
             "--root", str(boards), log=log)
    tasks = metrics["tasks"]

    def acc(task: str, key: str = "accuracy") -> float | None:
        if task not in tasks:
            return None
        v = tasks[task]["runs"][0].get(key)
        return None if v is None else 100.0 * v

    seconds = out / "train_seconds.txt"
    return {
        "run": run, "name": name, "n": metrics["n_samples"],
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
        "checkpoint": str(out / "checkpoint.safetensors"),
    }


def parameters(run: Run, n_objects: int) -> int:
    """Trainable parameters of a run's model (flow: the fitted tree's nodes)."""
    import torch

    if run.recipe == "timesformer":
        from vtsbench.models.timesformer import DualHeadTimesformer

        with torch.device("meta"):
            m = DualHeadTimesformer.from_config(run.config.get("config", "small"),
                                                run.config.get("modality", "rgb"),
                                                pretrained=False)
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
        f"Whole run {elapsed / 60:.1f} min.",
        "",
        f"Synthetic benchmark: `{info['dataset_name']}` built from `vtsbench simulate` "
        f"({info['dataset_desc']}), dataset_sha256 `{info['dataset_sha'][:16]}...`. "
        "Accuracy on the split's `test` part, one seed; latency per sample with a batch of one "
        "(median; forward pass only, reading excluded; flow: flow, features and tree). "
        "The paper's figures are on its own real recordings (83,000 RGB-D frames, "
        "ImageNet/SSv2-pretrained models), so they are a reference row, not a comparable entry.",
        "",
        "## Slip: state and direction",
        "",
        "| method | split | params | CPU latency ms | train s | state % | direction % "
        "(state given) | direction % end to end | within one bin % | angular error deg | "
        "test n (slipping) |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in slip:
        params = f"{r['params']} tree nodes" if r["run"].recipe == "flow" else _m(r["params"])
        lines.append(
            f"| {r['run'].method} | {r['run'].split} | {params} | {_ms(r['latency_ms'])} | "
            f"{_ms(r['train_s'])} | {_pct(r['state'])} | {_pct(r['direction'])} | "
            f"{_pct(r['direction_e2e'])} | {_pct(r['within_one'])} | "
            f"{'-' if r['angular'] is None else round(r['angular'])} | "
            f"{r['n']} ({r['n_dir']}) |")
    for p in paper_rows:
        if p["kind"] == "slip":
            for split in ("seen", "unseen_objects"):
                ref = PAPER[("slip", split)]
                lines.append(f"| {p['name']} | {split} (paper's data) | {_m(p['params'])} | "
                             f"{_ms(p['latency_ms'])} | - | {ref['state']} | "
                             f"{ref['direction']} | - | - | - | - |")
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


def findings(rows: list[dict[str, Any]], paper: list[dict[str, Any]]) -> list[str]:
    """Sentences comparing the baselines, from the figures."""
    out = []
    for split in ("unseen_objects", "seen"):
        by = {r["run"].recipe: r for r in rows if r["run"].split == split
              and r["run"].method in ("flow-quarter", "timesformer-small-rgb")}
        if set(by) != {"flow", "timesformer"}:
            continue
        f, t = by["flow"], by["timesformer"]
        if f["direction"] is None or t["direction"] is None:
            continue
        better = "beats" if t["direction"] > f["direction"] else (
            "ties" if t["direction"] == f["direction"] else "does not beat")
        ratio = (t["latency_ms"] / f["latency_ms"]) if f["latency_ms"] and t["latency_ms"] \
            else float("nan")
        out.append(
            f"- {split}: the small TimeSformer {better} the flow baseline (quarter "
            f"resolution) on direction "
            f"({t['direction']:.1f} % against {f['direction']:.1f} % with the state given, "
            f"{t['n_dir']} slipping test sequences; chance 12.5 %); state {t['state']:.1f} % "
            f"against {f['state']:.1f} % (chance 33.3 %). Flow is {ratio:.1f}x faster per "
            f"sequence ({f['latency_ms']:.1f} against {t['latency_ms']:.1f} ms).")
        if t["direction"] <= f["direction"] and t.get("n_slip_train"):
            out.append(
                f"  Trained from random weights for {t['run'].config.get('steps')} steps on "
                f"{t['n_slip_train']} slipping sequences (of {t['n_train']}; mirrored 4 ways, "
                f"drawn {t['run'].config.get('slip_oversample', 1)}x as often), "
                f"the state head learns and the direction head stays "
                f"{'near chance' if t['direction'] < 25.0 else 'well below flow'}; the flow "
                "baseline needs no training for direction. The paper's model starts from "
                "motion-pretrained (SSv2) weights and trains on 7,925 sequences.")
    flows = [r for r in rows if r["run"].method == "flow-quarter" and r["latency_ms"]]
    for p in paper:
        if p["kind"] == "slip" and p["device"] == "cpu" and flows:
            fast = min(r["latency_ms"] for r in flows)
            out.append(f"- Against the paper-size TimeSformer-base on this CPU "
                       f"({p['latency_ms']:.0f} ms a sequence), the flow baseline is "
                       f"{p['latency_ms'] / fast:.0f}x faster ({fast:.1f} ms).")
    for r in rows:
        if r["run"].recipe == "resnet" and r["object"] is not None:
            out.append(f"- {r['run'].method} on {r['dataset_name']} / {r['run'].split}: "
                       f"{r['object']:.1f} % over {r['classes']} classes (chance "
                       f"{100 / r['classes']:.1f} %), trained from random weights on "
                       f"{r['n_train']} frames.")
    return out or ["- (no runs)"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dataset", type=Path, required=True, help="synthetic dataset folder")
    ap.add_argument("--runs", type=Path, required=True, help="folder for runs and submissions")
    ap.add_argument("--leaderboards", type=Path, default=ROOT / "leaderboards")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results.md")
    ap.add_argument("--octopi", type=Path, default=None,
                    help="static RGB build of real videos (held-out takes in static_sessions)")
    ap.add_argument("--profile", choices=("demo", "results"), default="demo")
    ap.add_argument("--retrain", action="store_true", help="train every run afresh")
    ap.add_argument("--repeats", type=int, default=5, help="forward passes timed per paper model")
    args = ap.parse_args()

    import torch

    import vtsbench

    t0 = time.perf_counter()
    paths = {"synthetic": args.dataset, "octopi": args.octopi}
    log: list[str] = []
    rows = []
    for run in profile_runs(args.profile, args.octopi is not None):
        ds = paths[run.dataset]
        r = run_one(run, ds, args.runs, args.leaderboards, args.retrain, log)
        n_obj = len(vtsbench.load(ds).info.objects)
        r["params"] = tree_nodes(r["checkpoint"]) if run.recipe == "flow" else \
            parameters(run, n_obj)
        r["classes"] = n_obj
        train = vtsbench.load(ds).split(run.split, "train")
        r["n_train"] = len(train)
        if "state" in train.index.column_names:
            r["n_slip_train"] = train.index["state"].to_pylist().count("slip")
        rows.append(r)
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
        "dataset_desc": counts, "findings": findings(rows, paper_rows),
    }
    elapsed = time.perf_counter() - t0
    page = render(rows, paper_rows, info, log, elapsed)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(page)
    print()
    print("## Slip" + page.split("## What the figures say")[0].split("## Slip", 1)[1])
    print("\n".join(info["findings"]))
    print(f"\nresults page: {args.out}; leaderboards: {args.leaderboards}; runs: {args.runs}")


if __name__ == "__main__":
    main()
