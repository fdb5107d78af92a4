"""The live monitor: each built-in recipe's call on a window equals its predict on the same
sample, the ring buffer, the debounce, and the one-line refusals."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.fixtures.stream import (
    SLIP_SPLIT,
    STATIC_SPLIT,
    TINY_RESNET,
    TINY_TIMESFORMER,
    rgb_dataset,
    train,
)
from vtsbench.errors import VtsError
from vtsbench.recipes.base import WindowPredictor
from vtsbench.recipes.monitor import Monitor


@pytest.fixture(scope="module")
def rgb_ds(sim_recordings: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return rgb_dataset(sim_recordings, tmp_path_factory.mktemp("monitor") / "ds")


def _predicted(recipe: str, ckpt: Path, ds: Path, split: str, part: str) -> dict[str, dict]:
    from vtsbench.recipes import load_recipe

    out: dict[str, dict] = {}
    for r in load_recipe(recipe).predict(ckpt, ds, split, part):
        out.setdefault(r["sample_id"], {})[r["task"]] = r["pred"]
    return out


def _calls_on_samples(monitor: Monitor, view: Any) -> dict[str, Any]:
    """The monitor's last call on each sample's frames pushed one by one (reset between)."""
    calls = {}
    for i in range(len(view)):
        s = view[i]
        frames = s["rgb"] if s["rgb"].ndim == 4 else s["rgb"][None]
        monitor.reset()
        got = [monitor.push(f, timestamp=k / 25) for k, f in enumerate(frames)]
        assert all(c is None for c in got[:-1]) and got[-1] is not None
        calls[s["sample_id"]] = got[-1]
    return calls


@pytest.mark.parametrize("recipe,config", [
    ("flow", {}),
    ("flow", {"scale": 0.5, "shift_scale": 0.5, "preset": "ultrafast"}),
    ("timesformer", TINY_TIMESFORMER),
    ("timesformer", {**TINY_TIMESFORMER, "crop_px": None, "tta": False}),
])
def test_slip_monitor_equals_predict(rgb_ds: Path, tmp_path: Path, recipe: str,
                                     config: dict) -> None:
    import vtsbench

    ckpt = train(recipe, rgb_ds, tmp_path / "run", config)
    monitor = Monitor.from_checkpoint(recipe, ckpt, device="cpu")
    assert monitor.frames == 8 and monitor.size == (96, 128)
    view = vtsbench.load(rgb_ds).split(SLIP_SPLIT, "test")
    want = _predicted(recipe, ckpt, rgb_ds, SLIP_SPLIT, "test")
    calls = _calls_on_samples(monitor, view)
    assert len(calls) == len(view) >= 2
    for sid, call in calls.items():
        assert (call.raw_state, call.direction) == (want[sid]["state"], want[sid]["direction"])
        assert set(call.confidences["state"]) == {"static", "press", "slip"}
        assert abs(sum(call.confidences["state"].values()) - 1) < 1e-4
        assert call.latency_ms > 0 and call.frame_index == 7 and call.timestamp_s == 7 / 25


def test_object_monitor_equals_predict(rgb_ds: Path, tmp_path: Path) -> None:
    import vtsbench

    ckpt = train("resnet", rgb_ds, tmp_path / "run", TINY_RESNET, split=STATIC_SPLIT)
    monitor = Monitor.from_checkpoint("resnet", ckpt, device="cpu")
    assert monitor.frames == 1
    ds = vtsbench.load(rgb_ds)
    view = ds.split(STATIC_SPLIT, "test")
    want = _predicted("resnet", ckpt, rgb_ds, STATIC_SPLIT, "test")
    objects = list(ds.info.objects)
    for sid, call in _calls_on_samples(monitor, view).items():
        assert call.object == objects[want[sid]["object"]]
        assert call.state is None and call.direction is None


class _Recorder:
    """A fake window predictor: records each window it is given, calls `slip` on frames whose
    first pixel is odd."""

    def __init__(self, frames: int = 3, size: tuple[int, int] | None = (4, 5)) -> None:
        self.windows: list[np.ndarray] = []
        self.predictor = WindowPredictor(self, frames, size, {"state": ("static", "press",
                                                                        "slip")})

    def __call__(self, window: np.ndarray) -> dict[str, Any]:
        self.windows.append(window)
        p = [0.0, 0.0, 1.0] if window[-1, 0, 0, 0] % 2 else [0.8, 0.2, 0.0]
        return {"state_probs": p, "direction": 3}


def _frame(value: int, size: tuple[int, int] = (4, 5)) -> np.ndarray:
    return np.full((*size, 3), value, np.uint8)


def test_ring_buffer_windows_are_the_last_frames_in_order_without_reallocation() -> None:
    rec = _Recorder(frames=3)
    m = Monitor(rec.predictor)
    buf = m._buf
    assert m.push(_frame(0)) is None and not m.ready
    assert m.push(_frame(1)) is None and m.ready  # the next frame fills the window
    for k in range(2, 12):
        call = m.push(_frame(k), timestamp=k * 0.04)
        assert call is not None and call.frame_index == k and call.timestamp_s == k * 0.04
        assert [int(f[0, 0, 0]) for f in rec.windows[-1]] == [k - 2, k - 1, k]
        assert np.shares_memory(rec.windows[-1], buf)  # a view of the ring, not a copy
    assert m._buf is buf
    m.reset()
    assert m.push(_frame(50)) is None and m.push(_frame(51)) is None
    call = m.push(_frame(52))
    assert call is not None and call.frame_index == 2
    assert [int(f[0, 0, 0]) for f in rec.windows[-1]] == [50, 51, 52]


def test_any_size_checkpoint_takes_the_first_frame_size_and_clock() -> None:
    rec = _Recorder(frames=1, size=None)
    m = Monitor(rec.predictor)
    a = m.push(_frame(1, (6, 7)))
    b = m.push(_frame(1, (6, 7)))
    assert a is not None and b is not None and 0 <= a.timestamp_s <= b.timestamp_s
    with pytest.raises(VtsError, match=r"frame 2 is 4x5x3 uint8; the stream's first frame "
                                       r"was 6x7x3"):
        m.push(_frame(1))


def test_debounce_waits_for_k_calls_and_is_recorded() -> None:
    rec = _Recorder(frames=1)
    m = Monitor(rec.predictor, smoothing=3)
    raw = [0, 1, 1, 0, 1, 1, 1, 1, 0, 0, 0]  # odd: a slip call
    got = [m.push(_frame(v)) for v in raw]
    assert [c.raw_state for c in got] == ["slip" if v else "static" for v in raw]
    assert [c.state for c in got] == ["static"] * 6 + ["slip"] * 4 + ["static"]
    assert m.describe()["smoothing"] == {"rule": "debounce", "calls": 3}
    assert Monitor(rec.predictor).push(_frame(1)).state == "slip"  # 1: no smoothing
    for bad in (0, 101, 2.5, True):
        with pytest.raises(VtsError, match="smoothing must be"):
            Monitor(rec.predictor, smoothing=bad)


@pytest.mark.parametrize("frame,match", [
    (np.zeros((4, 5), np.uint8), r"frame 0 is 4x5 uint8; the monitor takes 4x5x3 uint8 RGB"),
    (np.zeros((4, 5, 4), np.uint8), r"frame 0 is 4x5x4 uint8"),
    (np.zeros((4, 5, 3), np.float32), r"frame 0 is 4x5x3 float32"),
    (np.zeros((8, 5, 3), np.uint8), r"frame 0 is 8x5x3 uint8; the checkpoint was trained at "
                                    r"4x5x3"),
    ([[0]], r"frame 0: a list, not a numpy array"),
])
def test_frames_of_another_size_or_layout_are_refused_in_one_line(frame: Any,
                                                                  match: str) -> None:
    m = Monitor(_Recorder().predictor)
    with pytest.raises(VtsError, match=match) as e:
        m.push(frame)
    assert "\n" not in str(e.value)
    assert m.push(_frame(1)) is None  # a refused frame is not kept


def test_checkpoint_refusals(rgb_ds: Path, tmp_path: Path) -> None:
    flow = train("flow", rgb_ds, tmp_path / "flow")
    with pytest.raises(VtsError, match="not a timesformer recipe checkpoint"):
        Monitor.from_checkpoint("timesformer", flow)
    with pytest.raises(VtsError, match="checkpoint not found"):
        Monitor.from_checkpoint("flow", tmp_path / "none.safetensors")
    m = Monitor.from_checkpoint("flow", flow)
    with pytest.raises(VtsError, match=r"trained at 96x128x3: a stream of another size"):
        m.push(_frame(0, (240, 320)))
    toy = tmp_path / "toy.py"
    toy.write_text("from vtsbench.recipes import Recipe\nclass T(Recipe):\n    name = 'toy'\n"
                   "RECIPE = T\n")
    with pytest.raises(VtsError, match="has no window_predictor"):
        Monitor.from_checkpoint(toy, flow)


def test_no_file_is_opened_after_construction(rgb_ds: Path, tmp_path: Path,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    import builtins
    import io
    import os

    import vtsbench

    m = Monitor.from_checkpoint("flow", train("flow", rgb_ds, tmp_path / "flow"))
    frames = vtsbench.load(rgb_ds).split(SLIP_SPLIT, "test")[0]["rgb"]

    def refuse(*a: Any, **k: Any) -> None:
        raise AssertionError(f"file opened: {a[:1]}")

    for mod, name in ((builtins, "open"), (io, "open"), (os, "open")):
        monkeypatch.setattr(mod, name, refuse)
    calls = [m.push(f) for f in np.concatenate([frames, frames])]
    assert sum(c is not None for c in calls) == 9


@pytest.mark.parametrize("config", [{}, {"scale": 0.5, "preset": "ultrafast"},
                                    {"shift_slope": True, "direction": "phase"}])
def test_flow_monitor_on_a_continuous_stream_equals_the_rule_on_each_window(
        rgb_ds: Path, tmp_path: Path, config: dict) -> None:
    """What `SlidingFlow` keeps from one window to the next (the flow's per-pair statistics,
    the grey frames of the global shift) gives every call the very features of its window
    computed afresh, bit for bit; a window that does not continue the previous one (a reset,
    frames dropped between pushes) is computed afresh."""
    import vtsbench
    from vtsbench.recipes import load_recipe
    from vtsbench.recipes.builtin.flow import SlidingFlow, classify, sequence_features

    ckpt = train("flow", rgb_ds, tmp_path / "flow", config)
    rec = load_recipe("flow")
    _, cfg, tree = rec._load(ckpt)
    view = vtsbench.load(rgb_ds).view("slip")
    clip = np.concatenate([view[i]["rgb"] for i in range(3)])
    m = Monitor.from_checkpoint("flow", ckpt)
    for k, f in enumerate(clip):
        call = m.push(f)
        if k >= 7:
            state, direction = classify(tree, cfg, clip[k - 7:k + 1], None)
            assert (call.raw_state, call.direction) == (("static", "press", "slip")[state],
                                                        direction)
    sliding = SlidingFlow(cfg["preset"], cfg["scale"], cfg["shift_scale"])
    for a in [*range(len(clip) - 7), 0, 5, 3]:  # then windows that do not follow on
        window = clip[a:a + 8]
        want = sequence_features(window, cfg, None)
        got = sequence_features(window, cfg, None, sliding(window))
        assert np.array_equal(got[0], want[0]) and got[1] == want[1], a


def test_the_live_monitoring_example_in_the_docs_runs(rgb_ds: Path, tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """docs/recipes.md, Live monitoring: its python block, as pasted."""
    import re

    from tests.fixtures.data import ROOT

    text = (ROOT / "docs" / "recipes.md").read_text(encoding="utf-8")
    section = text[text.index("## Live monitoring"):]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / "ds").symlink_to(rgb_ds)
    monkeypatch.chdir(tmp_path)
    namespace: dict[str, Any] = {"__name__": "docs_example"}
    exec(compile(code, "docs/recipes.md (Live monitoring)", "exec"), namespace)
    assert namespace["calls"] and all(c.state in ("static", "press", "slip")
                                      for c in namespace["calls"])
