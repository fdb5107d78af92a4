"""Running the results page's matrix: every step through the `vtsbench` command as a user runs
it (train, predict, eval, leaderboard add), resumable (a finished run is not trained again, a
submission newer than its checkpoint and already scored is reused), several runs side by side;
and the page's measurements beside the runs: the phase-correlation reference, parameter counts,
the paper-size models' latency, every checkpoint in the live monitor on a 25 fps stream, and the
stream evaluations of a folder of `vtsbench eval` outputs."""

from __future__ import annotations

import json
import os
import shutil
import statistics
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

from live import play, warm_up
from results_matrix import Run, expected_cost
from slip_effects import wilson

from vtsbench.evaluation.result import EvalResult, read_metrics
from vtsbench.evaluation.tasks import TASKS


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
    """Train, predict, eval and leaderboard-add one run; its figures (`scored_row`)."""
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
    evaluated = runs_dir / f"{name}.eval"
    if not reusable(sub, ckpt, evaluated / "metrics.json"):
        run_cli("predict", run.recipe, str(ckpt), "--dataset", str(ds),
                "--split", run.split, "--out", str(sub), "--method", run.method, log=log)
        run_cli("eval", str(sub), "--dataset", str(ds), "--split", run.split,
                "--out", str(evaluated), log=log)
    meta = json.loads(sub.with_suffix(".meta.json").read_text())
    result = read_metrics(evaluated / "metrics.json")
    # one entry per method, split and dataset version: a re-run replaces the method's earlier
    # entry on the same version; entries on an earlier version stay (listed apart)
    board = boards / result.dataset.name / run.split
    for old in board.glob(f"{run.method}-*.json"):
        if json.loads(old.read_text())["dataset"]["dataset_version"] == \
                result.dataset.dataset_version:
            old.unlink()
    run_cli("leaderboard", "add", str(sub), "--dataset", str(ds), "--split", run.split,
            "--root", str(boards), "--overwrite", log=log)
    seconds = out / "train_seconds.txt"
    return scored_row(run, name, result, meta, trained=trained,
                      train_s=float(seconds.read_text()) if seconds.exists() else None,
                      checkpoint=str(ckpt), submission=str(sub))


def reusable(sub: Path, ckpt: Path, scored: Path) -> bool:
    """Whether a submission is newer than its checkpoint, has its metadata and was scored after
    it was written: then a rerun that only adds a table costs no prediction."""
    return (sub.exists() and sub.with_suffix(".meta.json").exists() and scored.exists()
            and ckpt.stat().st_mtime < sub.stat().st_mtime <= scored.stat().st_mtime)


def _pct(v: float | None) -> float | None:
    return None if v is None else 100.0 * v


def scored_row(run: Run, name: str, result: EvalResult, meta: dict[str, Any], *,
               trained: bool, train_s: float | None, checkpoint: str,
               submission: str) -> dict[str, Any]:
    """A run's row of the page from its scores (first seed; rates in %) and its submission's
    metadata: each task's headline, direction's cascade and errors, state per true state."""
    first = {name: t.first for name, t in result.tasks.items()}

    def headline(task: str) -> float | None:
        r = first.get(task)
        return None if r is None else _pct(r.value(TASKS[task].headline))

    d0 = first["direction"].direction if "direction" in first else None
    s0 = first.get("state")
    ci = None if d0 is None else first["direction"].interval(TASKS["direction"].headline)
    return {
        "adjacent": None if d0 is None else _pct(d0.adjacent_error_share),
        "by_magnitude": None if d0 is None or d0.by_magnitude is None
        else d0.by_magnitude.to_dict(),
        "per_state": None if s0 is None or s0.per_state is None
        else {k: v.to_dict() for k, v in s0.per_state.items()},
        "environment": meta.get("environment"),
        "run": run, "name": name, "n": result.n_samples, "trained": trained,
        "train_s": train_s,
        "latency_ms": meta.get("latency_ms_per_sample_median"),
        "state": headline("state"), "direction": headline("direction"),
        "direction_e2e": None if d0 is None else _pct(d0.end_to_end_accuracy),
        "within_one": None if d0 is None else _pct(d0.within_one_bin),
        "angular": None if d0 is None else d0.mean_abs_angular_error_deg,
        "n_dir": first["direction"].n if d0 is not None else None,
        "object": headline("object"), "dataset_name": result.dataset.name,
        "dataset_sha": result.dataset.dataset_sha256,
        "checkpoint": checkpoint, "submission": submission,
        "direction_ci": None if ci is None else [100.0 * ci[0], 100.0 * ci[1]],
    }


def run_all(runs: list[Run], paths: dict[str, Path | None], runs_dir: Path, boards: Path,
            retrain: bool, jobs: int) -> tuple[list[dict[str, Any]], list[list[str]]]:
    """Every run's row and commands, in the matrix's order.

    Independent runs go side by side, one torch thread each (the recipes pin it): on 2 cores
    two single-threaded runs beat one two-threaded run, whose OpenMP threads stall when the
    machine is busy; each run's figures do not depend on what runs beside it. Longest first,
    so that the last run to start is a short one and neither worker idles while the other
    trains a long run alone."""
    logs: list[list[str]] = [[] for _ in runs]
    order = sorted(range(len(runs)), key=lambda k: -expected_cost(runs[k]))
    with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
        started = list(pool.map(lambda k: run_one(runs[k], paths[runs[k].dataset], runs_dir,
                                                  boards, retrain, logs[k]), order))
    return [started[order.index(k)] for k in range(len(runs))], logs


def complete_row(row: dict[str, Any], run: Run, dataset: Path, device: str) -> None:
    """Add what the scores do not hold to a run's row: parameters (flow: tree nodes), classes,
    training samples (and slips among them) and the device it ran on."""
    import vtsbench
    from vtsbench.recipes import fit_view

    n_obj = len(vtsbench.load(dataset).info.objects)
    row["params"] = tree_nodes(row["checkpoint"]) if run.recipe == "flow" else \
        parameters(run, n_obj)
    row["classes"] = n_obj
    train = fit_view(dataset, run.split, run.config.get("fit_parts") or ["train"])
    row["n_train"] = len(train)
    if "state" in train.index.column_names:
        row["n_slip_train"] = train.index["state"].to_pylist().count("slip")
    row["device"] = device if run.recipe != "flow" else "cpu"


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

    ds = vtsbench.load(dataset)
    ok, ids, times = [], [], []
    for s in ds.split(split, "test"):
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
    mm, px = distances(slip_motion(ds, ids))
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
    """Nodes of the flow recipe's fitted tree."""
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


def no_gpu() -> bool:
    """True when no CUDA device is visible (checked without importing torch)."""
    return not (os.environ.get("CUDA_VISIBLE_DEVICES", "x") != "" and
                (shutil.which("nvidia-smi") or Path("/dev/nvidia0").exists()))


#: The live stream every recipe is played: frames a second, as a GelSight Mini camera gives,
#: and the seconds of it each checkpoint gets by default (--stream-seconds).
STREAM_FPS, STREAM_SECONDS = 25.0, 15.0


def stream_frames(dataset: Path, split: str, n: int) -> tuple[Any, dict[str, Any]]:
    """About n frames of the split's test part played back to back as one stream at the
    dataset's resolution, and what they are: whole test sequences evenly spaced over the part
    (in its order, so every state is in it), or a static split's test frames one a sample."""
    import numpy as np

    import vtsbench

    ds = vtsbench.load(dataset)
    view = ds.split(split, "test")
    per = ds.info.frames_per_sequence if view.kind == "slip" else 1
    k = min(len(view), max(1, -(-n // per)))
    pos = np.unique(np.linspace(0, len(view) - 1, k).round().astype(int))
    rgb = view.read(pos, ("rgb",))["rgb"]
    frames = np.ascontiguousarray(rgb.reshape(-1, *rgb.shape[-3:]))
    return frames, {"kind": view.kind, "samples": len(pos), "of": len(view),
                    "frames": len(frames), "size": list(frames.shape[1:3])}


def live_stream(recipe: str, checkpoint: str, frames: Any, fps: float = STREAM_FPS
                ) -> dict[str, Any]:
    """The recipe's live monitor on the frames fed at fps from memory, as `vtsbench stream
    --realtime` plays a file (a frame the model is too slow for is dropped, as from a camera;
    each call's JSON line made and thrown away): its summary (fps sustained, dropped, latency
    p50/p95), window, what it calls and the torch and OpenCV threads it ran on; a checkpoint the
    monitor refuses: the reason. Torch's threads and deterministic mode are put back afterwards."""
    import torch

    from vtsbench.errors import VtsError
    from vtsbench.recipes.monitor import Monitor

    threads, strict = torch.get_num_threads(), torch.are_deterministic_algorithms_enabled()
    try:
        monitor = Monitor.from_checkpoint(recipe, checkpoint, device="cpu")
        warm_up(monitor, frames)  # the first torch call, OpenCV's first DIS
        import cv2

        used, cv_used = torch.get_num_threads(), cv2.getNumThreads()
        summary = play(monitor, frames, fps, "results page stream")
        classes = monitor.describe()["classes"]
        calls = "object" if "object" in classes else "state, direction"
        return {**{k: summary[k] for k in ("frames", "processed", "dropped", "calls",
                                           "wall_s", "fps_sustained", "latency_ms_p50",
                                           "latency_ms_p95")},
                "window": monitor.frames, "calls_what": calls, "torch_threads": used,
                "opencv_threads": cv_used}
    except VtsError as e:  # a checkpoint the monitor cannot run (depth), a stream too short
        return {"refused": e.reason}
    finally:
        torch.set_num_threads(threads)
        torch.use_deterministic_algorithms(strict)


def live_rows(rows: list[dict[str, Any]], paths: dict[str, Path | None], seconds: float
              ) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Every run's checkpoint in the live monitor, one after the other, each on `seconds` of
    its split's test part at STREAM_FPS (`stream_frames`, `live_stream`); and what the streams
    were and the load average as they began (for the page's sentence)."""
    n = max(1, round(seconds * STREAM_FPS))
    load = round(os.getloadavg()[0], 1)  # what else the 2 cores carry moves these figures
    cache: dict[tuple[str, str], tuple[Any, dict[str, Any]]] = {}
    out = []
    for r in rows:
        run = r["run"]
        key = (run.dataset, run.split)
        if key not in cache:
            cache[key] = stream_frames(paths[run.dataset], run.split, n)
        frames, what = cache[key]
        print(f"live stream: {run.method} ({run.split}), {len(frames)} frames at "
              f"{STREAM_FPS:g} fps", flush=True)
        out.append({"method": run.method, "recipe": run.recipe, "split": run.split,
                    "dataset": run.dataset, "stream": what,
                    **live_stream(run.recipe, r["checkpoint"], frames)})
    return out, {"fps": STREAM_FPS, "seconds": seconds, "load": load,
                 "streams": {
        f"{d}/{s}": what for (d, s), (_, what) in cache.items()}}


def read_stream_evals(folder: Path) -> list[dict[str, Any]]:
    """The stream scores of every `vtsbench eval` output in folder (FOLDER/*/metrics.json
    with a `stream` block, in name order): method, decision rule, dataset and figures."""
    from vtsbench.evaluation.stream_result import method_name

    out = []
    for path in sorted(folder.glob("*/metrics.json")):
        result = read_metrics(path)
        sr = result.stream
        if sr is None:
            continue
        out.append({"folder": path.parent.name,
                    "method": result.submission.method or method_name(sr),
                    "recipe": sr.recipe, "smoothing": sr.smoothing, "window": sr.window,
                    "dataset": result.dataset.to_dict(), "split": result.split,
                    "part": result.part, "n_episodes": sr.n_episodes,
                    "n_slip_episodes": sr.n_slip_episodes, "detected": sr.detected,
                    "delay_ms_p50": sr.delay_ms_p50, "delay_ms_p50_ci95": sr.delay_ms_p50_ci95,
                    "delay_ms_p90": sr.delay_ms_p90, "missed": sr.missed,
                    "false_alarms_per_min": sr.false_alarms_per_min,
                    "false_alarms": sr.false_alarms, "non_slip_minutes": sr.non_slip_minutes,
                    "direction_accuracy": sr.direction_accuracy,
                    "fps_sustained": sr.fps_sustained, "latency_ms_p95": sr.latency_ms_p95})
    return out
