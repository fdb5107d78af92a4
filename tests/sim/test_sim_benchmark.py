"""Named benchmark configurations and `vtsbench benchmark`: one call simulates, calibrates and
builds; a rerun keeps the finished steps; the dataset carries the benchmark's version."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from vtsbench.cli import app
from vtsbench.errors import VtsError
from vtsbench.sim import benchmark as B

runner = CliRunner()

TINY = B.BenchmarkConfig(name="v2-demo", dataset_version="2.0.0+test", description="tiny",
                         static=6, sequences=6, presses=8, size=(96, 128), holdout=2)


def test_v2_counts_are_the_papers_test_size() -> None:
    """v2: 5 of 15 objects held out leave 1,200 test sequences, and 3 sessions a static test
    session of 1,000 frames; the demo is the same generator and sensor."""
    v2, demo = B.BENCHMARKS["v2"], B.BENCHMARKS["v2-demo"]
    assert v2.sequences * 5 // v2.objects == 1200 and v2.sequences % 3 == 0
    assert v2.static // v2.sessions >= 1000
    same = ("generator", "gel", "size", "mm_per_px", "objects", "frames", "calibration_method")
    assert all(getattr(v2, k) == getattr(demo, k) for k in same)
    assert v2.generator == 2 and v2.dataset_version.startswith("2.")


def test_unknown_benchmark_and_another_seed() -> None:
    with pytest.raises(VtsError, match="unknown benchmark 'v9'"):
        B.get_config("v9")
    assert B.get_config("v2", seed=7).seed == 7 and B.get_config("v2").seed == 0


def test_make_benchmark_resumes_and_versions(tmp_path: Path, monkeypatch) -> None:
    import vtsbench

    monkeypatch.setitem(B.BENCHMARKS, "v2-demo", TINY)
    out = tmp_path / "bench"
    res = runner.invoke(app, ["benchmark", "v2-demo", str(out), "--workers", "1", "--quiet"])
    assert res.exit_code == 0, res.output
    assert "dataset version 2.0.0+test" in res.output
    ds = vtsbench.load(out / "dataset")
    assert ds.info.dataset_version == "2.0.0+test" and len(ds.slip) == 6
    doc = json.loads((out / "recordings" / B.CONFIG_FILE).read_text())
    assert doc["done"] == ["calibrate", "simulate"] and doc["config"]["static"] == 6
    # the dataset exists: one line, no traceback
    res = runner.invoke(app, ["benchmark", "v2-demo", str(out), "--quiet"])
    assert res.exit_code == 2 and "exists (use --overwrite" in res.output
    # a run that stopped after calibrating: the rerun neither simulates nor calibrates again
    shutil.rmtree(out / "dataset")

    def boom(*_a, **_k):
        raise AssertionError("a finished step ran again")

    import vtsbench.depth.calibration as cal
    import vtsbench.sim.simulate as sim

    monkeypatch.setattr(sim, "simulate", boom)
    monkeypatch.setattr(cal, "calibrate", boom)
    B.make_benchmark("v2-demo", out)
    assert vtsbench.load(out / "dataset").info.dataset_version == "2.0.0+test"
    # another configuration in the same folder is made afresh, not mixed with the old files
    monkeypatch.setitem(B.BENCHMARKS, "v2-demo", dataclasses.replace(TINY, static=3))
    with pytest.raises(AssertionError, match="ran again"):
        B.make_benchmark("v2-demo", out, overwrite=True)


def test_generator_2_balances_objects_within_each_state() -> None:
    """Any held-out set of objects holds as many sequences of every state (generator 2); the
    generator-1 plan is the one it always was."""
    from collections import Counter

    from vtsbench.sim.plan import make_plans

    plans = make_plans(0, 0, 3600, 0, 15, 3, per_state=True)
    per = Counter((p.object, p.state) for p in plans)
    assert len(per) == 45 and set(per.values()) == {80}
    held = sorted({p.object for p in plans})[:5]
    assert Counter(p.state for p in plans if p.object in held) == \
        {"static": 400, "press": 400, "slip": 400}
    old = make_plans(0, 0, 30, 0, 15, 3)
    assert [p.object for p in old] == [p.object for p in make_plans(0, 0, 30, 0, 15, 3)]
    assert [p.object for p in old] != [p.object for p in make_plans(0, 0, 30, 0, 15, 3,
                                                                     per_state=True)]
