"""How fast slip is caught: simulated continuous takes of unseen objects, streamed through
trained recipes and scored against their per-frame labels (docs/benchmarks.md, "Stream
evaluation: how fast slip is caught").

    .venv/bin/python benchmarks/stream_eval.py --out /tmp/stream-eval --workers 2

1. `vtsbench simulate-episodes` (240x320, 25 fps, 6 s takes, a quarter without slip; 8-frame
   slip samples every --sample-stride frames of each take);
2. the slip recipes trained on the seen objects' slip samples (`unseen_objects`, train): the
   flow tree (default config) and a CPU-sized TimeSformer (TSF_CONFIG);
3. streams of the test takes of `episode_unseen_objects` with debounce 1 and 3
   (`vtsbench predict --stream`), scored by `vtsbench eval`;
4. the simplest method on the same takes: the phase-correlation shift between the window's
   first and last frame, over a threshold fitted on the training takes, with the same monitor,
   debounce and scorer;
5. the direction rules on the test takes' slip windows (every window whose last frame is
   labelled slip, and each method's detection windows): flow's phase rule (what its stream
   uses without contact masks), the whole-frame phase correlation (the baseline's) and the
   mean DIS flow (flow's `mean_flow` rule), against the labels.

ResNet is not run: it is an object recipe (its monitor makes no state call), not a slip
detector; its stream speed is in "Live slip monitoring" (benchmarks/stream.py).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np
from machine import cpu_model  # benchmarks/machine.py: the shared machine line


def shift_px(window: np.ndarray) -> tuple[float, float]:
    """Phase-correlation shift (x right, y up, px) from the window's first frame to its last."""
    import cv2

    a = cv2.cvtColor(window[0], cv2.COLOR_RGB2GRAY).astype(np.float32)
    b = cv2.cvtColor(window[-1], cv2.COLOR_RGB2GRAY).astype(np.float32)
    (dx, dy), _ = cv2.phaseCorrelate(a, b)
    return float(dx), float(-dy)


def baseline_predictor(threshold_px: float, size: tuple[int, int], frames: int = 8) -> Any:
    """A window predictor: slip when the shift is over the threshold, in the shift's bin."""
    from vtsbench.labels import STATES, angle_to_class, motion_angle_deg
    from vtsbench.recipes.base import WindowPredictor

    def predict(window: np.ndarray) -> dict[str, Any]:
        dx, dy = shift_px(window)
        slip = float(np.hypot(dx, dy)) >= threshold_px
        probs = np.zeros(len(STATES))
        probs[STATES.index("slip" if slip else "static")] = 1.0
        return {"state_probs": probs,
                "direction": angle_to_class(motion_angle_deg(dx, dy)) if slip else None}

    return WindowPredictor(predict, frames, size, {"state": STATES},
                           note="phase-correlation shift threshold (benchmarks/stream_eval.py)")


def fit_threshold(dataset: Path, split: str) -> tuple[float, float]:
    """The shift threshold (px) that best separates slip windows from the others on the seen
    objects' takes (the split's train and val parts; balanced accuracy over 8-frame windows
    ending at every 2nd frame); and that score."""
    import vtsbench
    from vtsbench.errors import VtsError

    ds = vtsbench.load(dataset)
    shifts, slip = [], []
    for part in ("train", "val"):
        try:
            wins = ds.episodes.split(split, part).windows(length=8, stride=2)
        except VtsError:  # no such part
            continue
        for a in range(0, len(wins), 64):
            batch = wins.read(range(a, min(a + 64, len(wins))), ("rgb",))
            for i in range(len(batch["rgb"])):
                st = int(batch["state"][i][-1])
                if st < 0:
                    continue
                shifts.append(float(np.hypot(*shift_px(batch["rgb"][i]))))
                slip.append(st == 2)
    s, y = np.asarray(shifts), np.asarray(slip)
    if not y.any() or y.all():
        raise SystemExit(f"no slip and non-slip windows to fit the threshold on ({len(y)})")
    best = (0.0, 0.0)
    for t in np.unique(np.round(s, 3)):
        pred = s >= t
        bal = 0.5 * (pred[y].mean() + (~pred[~y]).mean())
        if bal > best[1]:
            best = (float(t), float(bal))
    return best


#: The TimeSformer streamed: the demo's small model (64 px input of a 128 px contact crop, each
#: frame's difference to the first and the crop's DIS flow) with the flow unmasked (the takes
#: and a live stream have no contact masks) and no test-time symmetry average (8 forward
#: passes a window: a monitor cannot afford them).
TSF_CONFIG = {"config": "small", "modality": "rgb", "image_size": 64, "crop_px": 128,
              "input": "delta+flow", "flow": "dis", "flow_mask": None, "pool": "cls+mean",
              "batch_size": 8, "checkpoint_every": 100, "tta": False, "threads": 1}
#: Frames after the onset within which a slip window counts as "near the onset".
NEAR_ONSET = 8


def direction_bins(window: np.ndarray) -> dict[str, int]:
    """The slip-direction bin of one (8, H, W, 3) window by three RGB rules: flow's rule on a
    stream (no contact masks: the phase rule, `global_shift`, the moving gel's phase
    correlation of the first frame with the last; the mean DIS flow where nothing moves), the
    whole frame's phase correlation (the baseline's) and the mean DIS flow (flow's `mean_flow`
    rule)."""
    import math

    from vtsbench.labels import angle_to_class, motion_angle_deg
    from vtsbench.recipes.builtin.flow import flow_features, global_shift, sequence_flow

    dx, dy, _ = global_shift(window)
    bx, by = shift_px(window)
    _, angle = flow_features(sequence_flow(window))
    phase = math.degrees(math.atan2(-dy, dx)) % 360.0 if dx or dy else angle
    return {"flow's phase rule": angle_to_class(phase),
            "whole-frame phase correlation": angle_to_class(motion_angle_deg(bx, by)),
            "mean DIS flow": angle_to_class(angle)}


def direction_study(dataset: Path, split: str, detections: dict[str, dict[str, int]]
                    ) -> dict[str, Any]:
    """Each rule of `direction_bins` against the labels on every test window whose last frame
    is slip (all; within NEAR_ONSET frames of the onset), and on each method's detection
    windows (`detections`: method -> episode id -> detection frame); with the median ratio of
    the measured shift to the object's true motion over the window."""
    import vtsbench
    from vtsbench.evaluation.metrics import bin_distance
    from vtsbench.sim.episodes import default_mm_per_px

    ds = vtsbench.load(dataset)
    wins = ds.episodes.split(split, "test").windows(length=8, stride=1)
    mm_per_px = default_mm_per_px(tuple(int(v) for v in ds.info.resolution))
    recs: list[dict[str, Any]] = []
    onsets: dict[str, int] = {}
    for a in range(0, len(wins), 64):
        b = wins.read(range(a, min(a + 64, len(wins))), ("rgb",))
        for i in range(len(b["rgb"])):
            st, eid = b["state"][i], b["episode_id"][i]
            last = int(b["frame_index"][i][-1])
            if int(st[-1]) == 2 and eid not in onsets:
                onsets[eid] = last
            wanted = {m for m, d in detections.items() if d.get(eid) == last}
            if int(st[-1]) != 2 and not wanted:
                continue
            true = int(b["direction"][i][-1])
            move_px = float(np.hypot(b["x_mm"][i][-1] - b["x_mm"][i][0],
                                     b["y_mm"][i][-1] - b["y_mm"][i][0])) / mm_per_px
            recs.append({"episode": eid, "frame": last, "slip": int(st[-1]) == 2,
                         "true": true, "since_onset": last - onsets.get(eid, last),
                         "true_px": move_px, "measured_px": float(np.hypot(
                             *shift_px(b["rgb"][i]))), "detected_by": sorted(wanted),
                         **direction_bins(b["rgb"][i])})
    rules = ("flow's phase rule", "whole-frame phase correlation", "mean DIS flow")

    def score(rs: list[dict[str, Any]]) -> dict[str, Any]:
        out: dict[str, Any] = {"windows": len(rs)}
        for r in rules:
            ok = [x[r] == x["true"] for x in rs]
            near = [bin_distance(x["true"], x[r]) <= 1 for x in rs]
            out[r] = {"exact": float(np.mean(ok)) if rs else None,
                      "within_one_bin": float(np.mean(near)) if rs else None}
        return out

    slip = [x for x in recs if x["slip"] and x["true"] >= 0]
    doc = {"all slip windows": score(slip),
           f"slip windows within {NEAR_ONSET} frames of the onset": score(
               [x for x in slip if x["since_onset"] < NEAR_ONSET]),
           "measured over true shift (median, whole frame)": float(np.median(
               [x["measured_px"] / x["true_px"] for x in slip if x["true_px"] > 0])),
           "true motion at the onset window (px, median)": float(np.median(
               [x["true_px"] for x in slip if x["since_onset"] == 0])),
           # a convention mismatch (image y down against labels y up) would put the errors
           # of every non-horizontal slip at 2-4 bins, not around 0
           "signed bin error of flow's phase rule (all slip windows)": {
               str(e): int(c) for e, c in zip(*np.unique(
                   [(x["flow's phase rule"] - x["true"] + 4) % 8 - 4 for x in slip],
                   return_counts=True), strict=True)}}
    for m in detections:
        doc[f"{m} detection windows"] = score(
            [x for x in recs if m in x["detected_by"] and x["true"] >= 0])
    return doc


def debounced(submission: Path, calls: int, out: Path) -> None:
    """A debounce-1 stream submission with `calls` calls of debounce applied afterwards: each
    call's reported state recomputed from the raw states by the monitor's rule (a state is
    reported once the raw calls have said it `calls` times in a row), the header's smoothing
    set; the latencies and speed are those of the debounce-1 run (a debounce costs no
    compute). `main` checks it against a real run of flow."""
    lines = []
    state = cand = None
    run = 0
    for raw_line in submission.read_bytes().splitlines():
        doc = json.loads(raw_line)
        if doc["type"] == "header":
            if doc["smoothing"]["calls"] != 1:
                raise SystemExit(f"{submission}: not a debounce-1 submission")
            doc["smoothing"]["calls"] = calls
            state = cand = None
            run = 0
        elif doc["type"] == "call" and doc["raw_state"] is not None:
            raw = doc["raw_state"]
            cand, run = (cand, run + 1) if raw == cand else (raw, 1)
            if state is None or run >= calls:
                state = raw
            doc["state"] = state
        lines.append(json.dumps(doc, separators=(",", ":")))
    out.write_text("\n".join(lines) + "\n")


def stream_baseline(dataset: Path, split: str, threshold: float, smoothing: int,
                    out: Path) -> None:
    """The baseline's stream submission, written as `vtsbench predict --stream` writes one."""
    import vtsbench
    from vtsbench.recipes.monitor import Monitor
    from vtsbench.recipes.stream import LineWriter, episode_source, run_stream

    ds = vtsbench.load(dataset)
    size = tuple(int(v) for v in ds.info.resolution)
    mon = Monitor(baseline_predictor(threshold, size), smoothing=smoothing,
                  recipe="phase-correlation")
    with open(out, "wb") as fh:
        for eid in ds.episodes.split(split, "test").ids:
            mon.reset()
            run_stream(mon, episode_source(dataset, eid), LineWriter(fh), device="cpu")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("/tmp/stream-eval"))
    ap.add_argument("--episodes", type=int, default=60)
    ap.add_argument("--objects", type=int, default=6)
    ap.add_argument("--seconds", type=float, default=6.0)
    ap.add_argument("--size", default="240x320")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--sample-stride", type=int, default=None,
                    help="frames between slip samples (default: simulate-episodes' default)")
    ap.add_argument("--tsf-steps", type=int, default=300)
    ap.add_argument("--skip-tsf", action="store_true", help="flow and the baseline only")
    args = ap.parse_args()

    from vtsbench.evaluation.stream import stream_result
    from vtsbench.recipes.runs import train_run
    from vtsbench.recipes.stream_submission import predict_streams
    from vtsbench.sim.episode_dataset import SAMPLE_STRIDE, EpisodeOptions, simulate_episodes

    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    ds = out / "takes"
    split = "episode_unseen_objects"
    times: dict[str, float] = {}
    h, w = (int(v) for v in args.size.split("x"))
    stride = SAMPLE_STRIDE if args.sample_stride is None else args.sample_stride
    t0 = time.perf_counter()
    simulate_episodes(ds, EpisodeOptions(args.episodes, args.objects, 3, 25.0, args.seconds,
                                         (h, w), 0, sample_stride=stride),
                      workers=args.workers, progress=True)
    times["simulate"] = time.perf_counter() - t0
    sp = {n: json.loads((ds / "meta" / "splits" / f"{n}.json").read_text())
          for n in ("unseen_objects", split)}
    held = {n: sorted(p["params"]["held_out_objects"]) for n, p in sp.items()}
    if held["unseen_objects"] != held[split]:
        raise SystemExit(f"the sample and episode splits hold out other objects: {held}")
    train_ids = sp["unseen_objects"]["parts"]["train"]
    t0 = time.perf_counter()
    trained = {"flow": train_run("flow", ds, "unseen_objects", out / "flow",
                                 progress=False).checkpoint}
    times["train flow"] = time.perf_counter() - t0
    if not args.skip_tsf:
        cfg = out / "timesformer.json"
        cfg.write_text(json.dumps({**TSF_CONFIG, "steps": args.tsf_steps}))
        t0 = time.perf_counter()
        trained["timesformer"] = train_run("timesformer", ds, "unseen_objects",
                                           out / "timesformer", config=cfg, device="cpu",
                                           progress=False).checkpoint
        times["train timesformer"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    threshold, bal = fit_threshold(ds, split)
    times["fit threshold"] = time.perf_counter() - t0
    rows, detections = [], {}
    # (method, checkpoint or None for the baseline, debounce, streamed or derived from k=1):
    # flow's debounce 3 is streamed, and checked against the one derived from its debounce 1;
    # the TimeSformer's is derived (its stream costs ~10x flow's)
    runs: list[tuple[str, Any, int, bool]] = []
    for n, c in trained.items():
        runs += [(n, c, 1, True), (n, c, 3, n != "timesformer")]
    runs += [("phase-correlation", None, 1, True), ("phase-correlation", None, 3, True)]
    for name, ckpt, k, streamed in runs:
        sub = out / f"{name}-k{k}.jsonl"
        t0 = time.perf_counter()
        if not streamed:
            debounced(out / f"{name}-k1.jsonl", k, sub)
        elif ckpt is None:
            stream_baseline(ds, split, threshold, k, sub)
        else:
            predict_streams(name, ckpt, ds, split, "test", sub, smoothing=k, device="cpu")
        times[f"stream {name} k{k}" + ("" if streamed else " (derived)")] = \
            time.perf_counter() - t0
        if name == "flow" and k > 1:
            derived = out / f"{name}-k{k}-derived.jsonl"
            debounced(out / f"{name}-k1.jsonl", k, derived)
            states = [[(d["frame_index"], d["state"]) for d in map(json.loads, f.read_bytes()
                       .splitlines()) if d["type"] == "call"] for f in (sub, derived)]
            if states[0] != states[1]:
                raise SystemExit("the debounce derived from flow's k=1 stream differs from "
                                 "its k=3 stream")
        sr = stream_result(sub, ds, split, "test").stream
        assert sr is not None
        d = sr.to_dict()
        detections[f"{name} k{k}"] = {e["episode_id"]: e["detection_frame"]
                                      for e in d["episodes"] if e["detection_frame"] is not None}
        rows.append({"method": name, "streamed": streamed,
                     **{k2: v for k2, v in d.items() if k2 != "episodes"}})
    t0 = time.perf_counter()
    directions = direction_study(ds, split, detections)
    times["direction study"] = time.perf_counter() - t0
    load = os.getloadavg()
    doc = {"machine": f"{os.cpu_count()} cores, {cpu_model()}", "load_average": load,
           "sample_stride": stride, "train_samples": len(train_ids),
           "threshold_px": threshold, "threshold_balanced_accuracy": bal,
           "held_out_objects": held[split], "seconds": times, "rows": rows,
           "directions": directions}
    (out / "results.json").write_text(json.dumps(doc, indent=1))

    def f(v: Any, d: int = 0, scale: float = 1.0) -> str:
        return "-" if v is None else f"{v * scale:.{d}f}"

    def ci(v: Any, d: int = 0, scale: float = 1.0) -> str:
        return "-" if v is None or v[0] is None else f"[{v[0] * scale:.{d}f}, {v[1] * scale:.{d}f}]"

    print(f"machine: {doc['machine']}; load average {load[0]:.2f}; sample stride {stride} "
          f"({len(train_ids)} train samples); threshold {threshold:.3f} px (balanced accuracy "
          f"{bal:.3f}); held out {held[split]}")
    print("| method | debounce | slip takes | delay p50 ms [95 % CI] | delay p90 ms | delay p50 "
          "/ p90 frames | missed % | false alarms / min [95 % CI] | direction at detection % "
          "[95 % CI] | within one bin % | fps sustained | latency p95 ms |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        k = f"{r['smoothing']}" + ("" if r["streamed"] else " (derived)")
        print(f"| {r['method']} | {k} | {r['n_slip_episodes']} of {r['n_episodes']}"
              f" | {f(r['delay_ms_p50'])} {ci(r['delay_ms_p50_ci95'])} | {f(r['delay_ms_p90'])}"
              f" | {f(r['delay_frames_p50'], 1)} / {f(r['delay_frames_p90'], 1)} | "
              f"{f(r['missed'], 1, 100)} | {f(r['false_alarms_per_min'], 2)} "
              f"{ci(r['false_alarms_per_min_ci95'], 2)} | {f(r['direction_accuracy'], 1, 100)} "
              f"{ci(r['direction_accuracy_ci95'], 0, 100)} | "
              f"{f(r['direction_within_one_bin'], 1, 100)} | {f(r['fps_sustained'], 1)} | "
              f"{f(r['latency_ms_p95'], 1)} |")
    print("direction rules (exact % / within one bin %):")
    for what, v in directions.items():
        if isinstance(v, dict) and "windows" in v:
            print(f"  {what} ({v['windows']} windows): " + "; ".join(
                f"{r} {f(x['exact'], 1, 100)} / {f(x['within_one_bin'], 1, 100)}"
                for r, x in v.items() if isinstance(x, dict)))
        else:
            print(f"  {what}: {v if isinstance(v, dict) else round(v, 3)}")
    print("seconds:", {k: round(v, 1) for k, v in times.items()})


if __name__ == "__main__":
    main()
