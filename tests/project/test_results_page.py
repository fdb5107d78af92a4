"""The results page generator (benchmarks/results.py): its runs, sentences and tables."""

from __future__ import annotations

import importlib.util
import sys

import numpy as np

from tests.fixtures.data import ROOT

SCRIPT = ROOT / "benchmarks" / "results.py"
sys.path.insert(0, str(SCRIPT.parent))


def _module():
    spec = importlib.util.spec_from_file_location("vtsbench_results_page", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # dataclasses look their module up
    spec.loader.exec_module(mod)
    return mod


def _row(mod, method, recipe, split, **kw):
    base = {"run": mod.Run(method, recipe, split), "name": method, "n": 30, "train_s": 12.0,
            "latency_ms": 5.0, "state": None, "direction": None, "direction_e2e": None,
            "within_one": None, "angular": None, "n_dir": None, "object": None,
            "dataset_name": "sim", "dataset_sha": "ab" * 32, "params": 7, "classes": 15}
    return {**base, **kw}


def test_profiles_and_findings() -> None:
    mod = _module()
    demo = mod.profile_runs("demo", octopi=False)
    full = mod.profile_runs("results", octopi=True)
    assert {r.method for r in demo} == {"flow-contact", "timesformer-small-rgb", "resnet18-rgb",
                                        "resnet18-depth"}
    v2 = mod.profile_runs("v2", octopi=False)
    assert {(r.method, r.split) for r in v2 if r.recipe == "timesformer"} == {
        ("timesformer-small-rgb", "unseen_objects"), ("timesformer-small-rgb", "seen"),
        ("timesformer-small-depth", "unseen_objects")}
    assert all(r.config.get("steps") == mod.V2_STEPS["timesformer"] for r in v2
               if r.recipe == "timesformer")
    assert "v2 profile" in mod.steps_note("v2", False, None)
    assert {r.method for r in full} == {"flow-contact", "timesformer-base-rgb",
                                        "timesformer-base-depth", "resnet50-rgb",
                                        "resnet50-depth", "resnet18-rgb"}
    assert [r.dataset for r in full].count("octopi") == 1
    tsf = next(r for r in full if r.method == "timesformer-base-rgb")
    assert tsf.config["config"] == "paper" and tsf.config["pretrained"] is False
    assert tsf.config["steps"] == mod.PAPER_STEPS["cpu"]["timesformer"]
    gpu = next(r for r in mod.profile_runs("results", False, gpu=True, pretrained="w")
               if r.method == "timesformer-base-rgb")
    assert gpu.config["steps"] == mod.PAPER_STEPS["gpu"]["timesformer"]
    assert gpu.config["pretrained_path"] == "w" and gpu.config["pretrained"] is True
    assert "fewer steps" in mod.steps_note("results", False, None)
    assert "not run" in mod.steps_note("demo", False, None)
    rows = [_row(mod, "flow-shift", "flow", "unseen_objects", state=90.0, direction=97.3,
                 n_dir=37, latency_ms=4.0, adjacent=100.0),
            _row(mod, "timesformer-small-rgb", "timesformer", "unseen_objects", state=95.5,
                 direction=80.0, n_dir=37, latency_ms=20.0, params=1_900_000, adjacent=75.0)]
    refs = [{"split": "unseen_objects", "direction": 90.0, "n_dir": 37, "latency_ms": 2.0}]
    text = " ".join(mod.findings(rows, [], refs))
    assert "7.3 points above the phase correlation" in text
    assert "10.0 points below the phase correlation" in text
    assert "75 % of the direction errors on the adjacent bin" in text and "5.0x" in text
    paper = [{"kind": "slip", "device": "cpu", "latency_ms": 2000.0}]
    assert "500x faster" in " ".join(mod.findings(rows, paper))
    # intervals: apart or overlapping; RGB against depth-only
    rows[0]["direction_ci"], refs[0]["direction_ci"] = [93.0, 99.0], [85.0, 94.0]
    rows[1]["direction_ci"] = [70.0, 88.0]
    depth = _row(mod, "timesformer-small-depth", "timesformer", "unseen_objects", state=90.0,
                 direction=70.0, n_dir=37, latency_ms=20.0)
    depth["run"].config["modality"] = "depth"
    text = " ".join(mod.findings([*rows, depth], [], refs))
    assert "[95 % interval 93.0-99.0]" in text and "the intervals overlap" in text
    assert "TimeSformer on RGB 80.0 % direction, above the same model on depth alone (70.0 %)" \
        in text


def test_effect_table_and_wilson() -> None:
    import slip_effects as E

    lo, hi = E.wilson(8, 10)
    assert 0.49 < lo < 0.5 and 0.94 < hi < 0.95 and E.wilson(0, 0) is None
    truth = {"a": {"direction": 1, "profile": "steady", "contact": "kept", "turn": 0.2,
                   "group": "g"},
             "b": {"direction": 2, "profile": "jerk", "contact": "lost", "turn": 1.5,
                   "group": "g"}}
    rows = E.effect_table(truth, [("m %", {"a": True, "b": False}), ("ref %", {"a": False})])
    assert "| speed profile | jerk | 1 | 0.0 [0-79] | - |" in rows
    assert "| rotation over the window, deg | [0, 0.5) | 1 | 100.0 [21-100] | 0.0 [0-79] |" \
        in rows
    assert "| object group | g | 2 | 50.0 [9-91] | 0.0 [0-79] |" in rows


def test_page_has_tables_references_and_paper_rows() -> None:
    mod = _module()
    bins = {"bins": [{"lo_mm": 0.0, "hi_mm": 0.1, "n": 0, "accuracy": None, "px_median": None},
                     {"lo_mm": 0.1, "hi_mm": None, "n": 20, "accuracy": 0.5,
                      "px_median": 12.0}]}
    rows = [_row(mod, "flow-shift", "flow", "seen", state=70.0, direction=40.0, n_dir=20,
                 angular=30.0, by_magnitude=bins,
                 per_state={"static": {"n": 3, "accuracy": 1.0},
                            "press": {"n": 0, "accuracy": None}}),
            _row(mod, "resnet18-rgb", "resnet", "static_sessions", object=80.0,
                 params=11_200_000)]
    paper = [{"name": "timesformer-base (paper)", "kind": "slip", "params": 121_000_000,
              "latency_ms": 3100.0, "device": "cpu"},
             {"name": "resnet50 (paper)", "kind": "static", "params": 23_500_000,
              "latency_ms": 60.0, "device": "cpu"}]
    info = {"dataset": "d", "runs": "r", "profile": "demo", "machine": "2 cores",
            "devices": "CPU", "dataset_name": "sim", "dataset_sha": "ab" * 32,
            "dataset_desc": "tiny", "leaderboards": "lb", "findings": ["- x"],
            "references": [{"split": "seen", "direction": 92.6, "n_dir": 20, "latency_ms": 3.0,
                            "by_magnitude": bins}]}
    page = mod.render(rows, paper, info, ["vtsbench train flow"], 60.0)
    assert "| flow-shift | seen | cpu | 7 tree nodes | 5.0 |" in page
    assert "| 40.0 | - |" in page  # the direction's 95 % interval column
    assert "| phase correlation, first and last frame (reference) | seen | cpu |" in page
    assert "| 99.68 | 96.95 |" in page and "| 95.5 | 91.5 |" in page
    assert "| [0, 0.1) | 0 | - | - |" in page and "| [0.1, inf) | 20 | 50.0 (12.0) |" in page
    assert "| flow-shift | seen | 100.0 (3) | - (0) |" in page
    assert "| resnet18-rgb | sim / static_sessions | 15 | 11.2 M |" in page
    assert "98.8" in page and "96.06" in page and "3100" in page


def test_other_dataset_table() -> None:
    mod = _module()
    assert mod.other_table(None) == []
    other = {"dataset_sha256": "cd" * 32, "label": "seed 7; ",
             "references": [{"split": "seen", "direction": 90.0}],
             "rows": [{"method": "flow-shift", "split": "seen", "state": 80.0,
                       "direction": 95.0, "adjacent": 100.0, "object": None}]}
    text = "\n".join(mod.other_table(other))
    assert "seed 7; dataset_sha256 `cdcdcdcdcdcdcdcd...`" in text
    assert "| flow-shift | seen | 80.0 | 95.0 | 100.0 | - | 90.0 |" in text


def _live(method, split, **kw):
    base = {"method": method, "recipe": "flow", "split": split, "dataset": "synthetic",
            "frames": 375, "processed": 375, "dropped": 0, "calls": 368, "wall_s": 15.0,
            "fps_sustained": 25.0, "latency_ms_p50": 12.34, "latency_ms_p95": 20.0,
            "window": 8, "calls_what": "state, direction", "torch_threads": 2,
            "opencv_threads": 2}
    return {**base, **kw}


def test_live_stream_table() -> None:
    mod = _module()
    assert mod.live_table([], None) == []
    meta = {"fps": 25.0, "seconds": 15.0, "load": 2.5, "streams": {
        "synthetic/unseen_objects": {"kind": "slip", "samples": 47, "of": 1200,
                                     "frames": 376, "size": [240, 320]},
        "synthetic/static_sessions": {"kind": "static", "samples": 375, "of": 1000,
                                      "frames": 375, "size": [240, 320]}}}
    live = [_live("flow-contact", "unseen_objects"),
            _live("timesformer-small-rgb", "unseen_objects", dropped=300, processed=75,
                  recipe="timesformer", torch_threads=1,
                  fps_sustained=5.0, latency_ms_p50=180.0, latency_ms_p95=230.5),
            {"method": "timesformer-small-depth", "recipe": "timesformer",
             "split": "unseen_objects", "dataset": "synthetic",
             "refused": "the checkpoint reads depth; a live stream gives RGB frames alone"},
            _live("resnet18-rgb", "static_sessions", window=1, calls_what="object",
                  recipe="resnet", torch_threads=1,
                  latency_ms_p50=30.0, latency_ms_p95=41.0)]
    text = "\n".join(mod.live_table(live, meta))
    assert "## Live stream: what each recipe sustains" in text
    assert "at 240x320 (unseen_objects: 376 frames, 47 of its 1200 test sequences; " \
        "static_sessions: 375 frames, 375 of its 1000 test frames, one a static sample;" in text
    assert "| flow-contact | unseen_objects | state, direction | 8 | 12.3 | 20.0 | 25.0 | " \
        "0.0 (0 of 375) |" in text
    assert "| timesformer-small-rgb | unseen_objects | state, direction | 8 | 180 | 230 | " \
        "5.0 | 80.0 (300 of 375) |" in text
    assert "| resnet18-rgb | static_sessions | object | 1 |" in text
    assert "timesformer-small-depth |" not in text
    assert "- Not streamed: timesformer-small-depth (unseen_objects): the checkpoint reads " \
        "depth" in text
    assert "- Keeps up with the 25 fps stream (no frame dropped): flow-contact " \
        "(unseen_objects), resnet18-rgb (static_sessions); drops frames: " \
        "timesformer-small-rgb (unseen_objects) 80.0 %." in text
    assert "(load average 2.5 as the streams began)" in text
    assert "torch's as each checkpoint's config pins them (1; the flow recipe uses no torch), " \
        "OpenCV's 2 (" in text


def _stream_metrics(method: str | None, smoothing: int) -> dict:
    """A metrics.json of `vtsbench eval` on a stream submission (the shape of its stream
    block, two episodes)."""
    episodes = [
        {"episode_id": "episode-000003", "object": "fabric", "slip": False,
         "onset_frame": None, "detection_frame": None, "delay_frames": None, "delay_ms": None,
         "direction_true": None, "direction_called": None, "false_alarms": 3,
         "non_slip_s": 5.24, "calls": 143},
        {"episode_id": "episode-000005", "object": "screw_thread", "slip": True,
         "onset_frame": 66, "detection_frame": 68, "delay_frames": 2, "delay_ms": 80.0,
         "direction_true": 1, "direction_called": 1, "false_alarms": 2, "non_slip_s": 2.36,
         "calls": 143}]
    stream = {"metric_version": "1.0", "recipe": "flow", "checkpoint_sha256": "95" * 32,
              "smoothing": smoothing, "window": 8, "n_episodes": 2, "n_slip_episodes": 1,
              "detected": 1, "missed": 0.0, "missed_ci95": [0.0, 0.0],
              "delay_ms_p50": 80.0, "delay_ms_p50_ci95": [40.0, 160.0],
              "delay_ms_p90": 320.0, "delay_ms_p90_ci95": [144.0, 520.0],
              "delay_frames_p50": 2.0, "delay_frames_p90": 8.0, "false_alarms": 5,
              "non_slip_minutes": 0.126667, "false_alarms_per_min": 39.47,
              "false_alarms_per_min_ci95": [20.5, 38.3], "direction_accuracy": 0.5333,
              "direction_accuracy_ci95": [0.27, 0.8], "direction_within_one_bin": 0.87,
              "fps_sustained": 78.274, "latency_ms_p95": 21.7465, "episodes": episodes}
    return {"metric_version": "1.0", "vtsbench_version": "0.1.0",
            "dataset": {"name": "takes", "dataset_version": "1.0.0",
                        "dataset_sha256": "84" * 32},
            "split": "episode_unseen_objects", "part": "test", "kind": "episode",
            "n_samples": 2,
            "submission": {"file": "flow-k1.jsonl", "sha256": "75" * 32, "method": method,
                           "recipe": "flow", "seeds": [0]},
            "tasks": {}, "stream": stream}


def test_stream_evaluation_table(tmp_path) -> None:
    import json

    mod = _module()
    for name, method, k in (("ev-flow-k1", "flow (debounce 1)", 1), ("ev-flow-k3", None, 3)):
        (tmp_path / name).mkdir()
        (tmp_path / name / "metrics.json").write_text(json.dumps(_stream_metrics(method, k)))
    window = _stream_metrics("flow", 1)
    del window["stream"]
    (tmp_path / "ev-window").mkdir()  # a window submission's scores: no stream block, skipped
    (tmp_path / "ev-window" / "metrics.json").write_text(json.dumps(window))
    evals = mod.read_stream_evals(tmp_path)
    assert [e["folder"] for e in evals] == ["ev-flow-k1", "ev-flow-k3"]
    assert [e["method"] for e in evals] == ["flow (debounce 1)", "flow (debounce 3)"]
    assert mod.stream_eval_table([], None) == []
    text = "\n".join(mod.stream_eval_table(evals, "/tmp/streams"))
    assert "## Slip caught on a stream: detection delay and false alarms" in text
    assert "in `/tmp/streams` (2; `takes` 1.0.0 (dataset_sha256 `8484848484848484...`), " \
        "episode_unseen_objects / test)" in text
    assert "| flow (debounce 1) | 1 | 2 (1) | 80 [40, 160] | 320 | 0.0 | 39.5 | 53.3 | 78.3 | " \
        "21.7 |" in text
    assert "| flow (debounce 3) | 3 |" in text


def test_page_sections_and_command_with_streams() -> None:
    mod = _module()
    rows = [_row(mod, "flow-shift", "flow", "seen", state=70.0, direction=40.0, n_dir=20)]
    info = {"dataset": "d", "runs": "r", "profile": "v2", "machine": "2 cores",
            "devices": "CPU", "dataset_name": "sim", "dataset_sha": "ab" * 32,
            "dataset_desc": "tiny", "leaderboards": "lb", "findings": ["- x"]}
    page = mod.render(rows, [], info, [], 60.0)
    assert "## Live stream" not in page and "## Slip caught on a stream" not in page
    assert "--profile v2\n```" in page
    meta = {"fps": 25.0, "seconds": 2.0, "streams": {"synthetic/seen": {
        "kind": "slip", "samples": 7, "of": 30, "frames": 56, "size": [24, 32]}}}
    evals = [{"method": "flow (debounce 1)", "smoothing": 1, "n_episodes": 2,
              "n_slip_episodes": 1, "delay_ms_p50": None, "delay_ms_p50_ci95": [None, None],
              "delay_ms_p90": None, "missed": 1.0, "false_alarms_per_min": None,
              "direction_accuracy": None, "fps_sustained": None, "latency_ms_p95": None,
              "dataset": {"name": "t", "dataset_version": "1", "dataset_sha256": "cd" * 32},
              "split": "episode_unseen_objects", "part": "test"}]
    page = mod.render(rows, [], {**info, "live": [_live("flow-shift", "seen")],
                                 "live_meta": meta, "streams": "streams",
                                 "stream_seconds": 2.0,
                                 "stream_evals": evals}, [], 60.0)
    assert "--profile v2 --stream-seconds 2 --streams streams\n```" in page
    live, slip, said = (page.index(h) for h in ("## Live stream", "## Slip caught on a stream",
                                                 "## What the figures say"))
    assert live < slip < said
    assert "| flow (debounce 1) | 1 | 2 (1) | - | - | 100.0 | - | - | - | - |" in page


def test_stream_frames_and_live_stream(vts_dataset, tmp_path) -> None:
    """The stream the page plays: whole test sequences evenly spaced, at the dataset's size;
    a flow checkpoint in the live monitor on it; a file that is not a checkpoint refused in one
    line; torch's threads left as they were."""
    import torch

    import vtsbench
    from tests.fixtures.stream import train

    mod = _module()
    d = vtsbench.load(vts_dataset)
    t, test = d.info.frames_per_sequence, d.split("unseen_objects", "test")
    frames, what = mod.stream_frames(vts_dataset, "unseen_objects", 2 * t)
    assert what == {"kind": "slip", "samples": min(2, len(test)), "of": len(test),
                    "frames": len(frames), "size": list(d.info.resolution)}
    assert len(frames) == what["samples"] * t
    assert frames.shape[1:] == (*d.info.resolution, 3) and frames.dtype.name == "uint8"
    assert (frames[:t] == test.sample(0, ("rgb",))["rgb"]).all()
    assert (frames[-t:] == test.sample(len(test) - 1, ("rgb",))["rgb"]).all()
    threads = torch.get_num_threads()
    ckpt = train("flow", vts_dataset, tmp_path / "flow")
    # 3.2 s of stream: a loaded machine drops frames, and a stream of only two windows may
    # leave fewer than a window to the monitor (no call: refused)
    played = np.concatenate([frames] * 10)
    out = mod.live_stream("flow", str(ckpt), played, fps=50.0)
    assert out["frames"] == len(played) and out["window"] == t
    assert out["processed"] + out["dropped"] == out["frames"] and out["calls"] >= 1
    assert out["calls_what"] == "state, direction" and out["latency_ms_p95"] >= 0
    assert out["opencv_threads"] >= 1
    assert 0 < out["fps_sustained"] <= 50.0 * 1.2
    run = {"run": mod.Run("flow-x", "flow", "unseen_objects"), "checkpoint": str(ckpt)}
    # 2 s: enough windows for a call even when a loaded machine drops frames
    live, meta = mod.live_rows([run], {"synthetic": vts_dataset}, 2.0)
    assert [(r["method"], r["split"], r["window"]) for r in live] == [
        ("flow-x", "unseen_objects", t)]
    assert meta["fps"] == 25.0 and meta["seconds"] == 2.0 and meta["load"] >= 0
    assert meta["streams"]["synthetic/unseen_objects"]["frames"] == live[0]["frames"]
    bad = tmp_path / "not-a-checkpoint.safetensors"
    bad.write_bytes(b"no")
    refused = mod.live_stream("flow", str(bad), frames)
    assert set(refused) == {"refused"} and "\n" not in refused["refused"]
    assert torch.get_num_threads() == threads
