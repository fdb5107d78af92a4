"""Speed against accuracy of the reference recipes: train, predict, score, enter the leaderboards
and write the results page (docs/results.md).

Run: .venv/bin/python benchmarks/results.py --dataset demo-data/dataset --runs demo-data/runs \
        [--leaderboards leaderboards] [--out docs/results.md] [--octopi DATASET] [--profile demo]
        [--stream-seconds 15] [--streams FOLDER]

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
machine's CPU (and GPU when there is one). Then every checkpoint in the live monitor, as
`vtsbench stream --realtime` runs it, on --stream-seconds of its split's test part at 25 fps
(frames per second sustained, dropped, p50/p95 latency); with --streams FOLDER, the detection
delay and false alarms of the stream submissions `vtsbench eval` scored there. Prints the table
and writes the page.

The runs are declared in results_matrix.py, run by results_runner.py and written up by
results_page.py; this script only reads the options and calls them in order.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from machine import machine  # noqa: E402
from results_matrix import (  # noqa: E402, F401  (the matrix's names, read by tests)
    PAPER,
    PAPER_STEPS,
    SLIP_SPLITS,
    V2_STEPS,
    Run,
    profile_runs,
    select,
    steps_note,
)
from results_page import (  # noqa: E402, F401  (the page's names, read by tests)
    findings,
    live_table,
    other_table,
    render,
    stream_eval_table,
    summary_json,
    write_page,
)
from results_runner import (  # noqa: E402, F401  (the runner's names, read by tests)
    STREAM_SECONDS,
    complete_row,
    live_rows,
    live_stream,
    no_gpu,
    paper_size_latency,
    phase_reference,
    read_stream_evals,
    run_all,
    run_cli,
    stream_frames,
)
from slip_effects import slip_truth  # noqa: E402


def parse_args() -> argparse.Namespace:
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
    ap.add_argument("--stream-seconds", type=float, default=STREAM_SECONDS,
                    help="seconds of 25 fps stream each checkpoint is played in the live "
                         "monitor (its split's test part, back to back); 0: no live table")
    ap.add_argument("--streams", type=Path, default=None,
                    help="folder of `vtsbench eval` outputs of stream submissions "
                         "(FOLDER/*/metrics.json): their detection-delay table")
    ap.add_argument("--summary", type=Path, default=None,
                    help="also write the rows as JSON here (accuracies, devices, versions)")
    return ap.parse_args()


def shown_path(path: Path) -> str:
    """A path as the page shows it: relative to the repository when inside it."""
    full = path.resolve()
    return os.path.relpath(full, ROOT) if full.is_relative_to(ROOT) else str(path)


def main() -> None:
    args = parse_args()

    import torch

    import vtsbench

    t0 = time.perf_counter()
    stream_evals = [] if args.streams is None else read_stream_evals(args.streams)
    if args.streams is not None and not stream_evals:
        sys.exit(f"{args.streams}: no metrics.json of a stream submission in its folders "
                 "(FOLDER/*/metrics.json with a stream block, as `vtsbench eval` writes)")
    paths = {"synthetic": args.dataset, "octopi": args.octopi}
    gpu = torch.cuda.is_available()
    device = "cuda" if gpu else "cpu"
    runs = select(profile_runs(args.profile, args.octopi is not None, gpu=gpu,
                               pretrained=args.pretrained), args.splits, args.steps)
    jobs = args.jobs or (2 if args.profile in ("demo", "v2") and no_gpu() else 1)
    rows, logs = run_all(runs, paths, args.runs, args.leaderboards, args.retrain, jobs)
    log: list[str] = []
    for run, r, run_log in zip(runs, rows, logs, strict=True):
        log += run_log
        complete_row(r, run, paths[run.dataset], device)
    splits = [sp for sp in SLIP_SPLITS if any(r.split == sp for r in runs)]
    refs = [phase_reference(args.dataset, split) for split in splits]
    effects = {sp: slip_truth(args.dataset, sp) for sp in splits} if args.profile == "v2" else {}
    run_cli("leaderboard", "render", "--root", str(args.leaderboards), log=log)
    devices = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
    paper_rows = []
    for dev in devices:
        paper_rows += paper_size_latency(dev, args.repeats)
    paper_rows = [p for p in paper_rows if p["device"] == "cpu"] + \
        [dict(p, name=f"{p['name']} on GPU") for p in paper_rows if p["device"] != "cpu"]
    # after the runs and the paper models' latency, one stream at a time: the recipes pin
    # torch's threads, which live_stream puts back
    live, live_meta = live_rows(rows, paths, args.stream_seconds) if args.stream_seconds > 0 \
        else ([], None)
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
        "live": live, "live_meta": live_meta,
        "stream_seconds": None if args.stream_seconds == STREAM_SECONDS else args.stream_seconds,
        "streams": None if args.streams is None else shown_path(args.streams),
        "stream_evals": stream_evals,
    }
    elapsed = time.perf_counter() - t0
    page = render(rows, paper_rows, info, log, elapsed)
    write_page(args.out, page)
    print()
    print("## Slip" + page.split("## What the figures say")[0].split("## Slip", 1)[1])
    print("\n".join(info["findings"]))
    if args.summary is not None:
        args.summary.write_text(summary_json(rows, info, elapsed))
    print(f"\nresults page: {args.out}; leaderboards: {args.leaderboards}; runs: {args.runs}")


if __name__ == "__main__":
    main()
