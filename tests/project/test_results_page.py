"""The results page generator (benchmarks/results.py): its runs, sentences and tables."""

from __future__ import annotations

import importlib.util
import sys

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
