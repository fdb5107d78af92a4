"""The results page generator (benchmarks/results.py): its runs, sentences and tables."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "results.py"


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
    assert {r.method for r in demo} == {"flow-quarter", "timesformer-small-rgb", "resnet18-rgb",
                                        "resnet18-depth"}
    assert {r.method for r in full} - {r.method for r in demo} == {"flow-full"}
    assert [r.dataset for r in full].count("octopi") == 1
    rows = [_row(mod, "flow-quarter", "flow", "unseen_objects", state=60.0, direction=46.0,
                 n_dir=37, latency_ms=4.0),
            _row(mod, "timesformer-small-rgb", "timesformer", "unseen_objects", state=95.5,
                 direction=20.0, n_dir=37, latency_ms=20.0, params=1_900_000)]
    text = " ".join(mod.findings(rows, []))
    assert "does not beat" in text and "5.0x faster" in text and "46.0 %" in text
    rows[1].update(n_slip_train=75, n_train=216)
    assert "75 slipping sequences (of 216" in " ".join(mod.findings(rows, []))
    paper = [{"kind": "slip", "device": "cpu", "latency_ms": 2000.0}]
    assert "500x faster" in " ".join(mod.findings(rows, paper))
    rows[1]["direction"] = 50.0
    assert "TimeSformer beats" in " ".join(mod.findings(rows, []))


def test_page_has_both_tables_and_paper_rows() -> None:
    mod = _module()
    rows = [_row(mod, "flow-quarter", "flow", "seen", state=70.0, direction=40.0, n_dir=20,
                 angular=30.0),
            _row(mod, "resnet18-rgb", "resnet", "static_sessions", object=80.0,
                 params=11_200_000)]
    paper = [{"name": "timesformer-base (paper)", "kind": "slip", "params": 121_000_000,
              "latency_ms": 3100.0, "device": "cpu"},
             {"name": "resnet50 (paper)", "kind": "static", "params": 23_500_000,
              "latency_ms": 60.0, "device": "cpu"}]
    info = {"dataset": "d", "runs": "r", "profile": "demo", "machine": "2 cores",
            "devices": "CPU", "dataset_name": "sim", "dataset_sha": "ab" * 32,
            "dataset_desc": "tiny", "leaderboards": "lb", "findings": ["- x"]}
    page = mod.render(rows, paper, info, ["vtsbench train flow"], 60.0)
    assert "| flow-quarter | seen | 7 tree nodes | 5.0 |" in page
    assert "| 99.68 | 96.95 |" in page and "| 95.5 | 91.5 |" in page
    assert "| resnet18-rgb | sim / static_sessions | 15 | 11.2 M |" in page
    assert "98.8" in page and "96.06" in page and "3100" in page
