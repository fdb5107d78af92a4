"""`vtsbench stream`: JSON lines from a video file, a dataset episode and a camera, valid after
any failure mid-stream; dropped frames counted with a slow model; the bad-input lines."""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

from tests.fixtures.data import real_dir
from tests.fixtures.stream import rgb_dataset, train
from vtsbench.cli import app
from vtsbench.errors import VtsError
from vtsbench.recipes.base import WindowPredictor
from vtsbench.recipes.monitor import Monitor
from vtsbench.recipes.stream import LineWriter, Source, line_errors, run_stream


@pytest.fixture(scope="module")
def flow_run(sim_recordings: Path, tmp_path_factory: pytest.TempPathFactory
             ) -> tuple[Path, Path]:
    """An RGB-only dataset (96x128) and a flow checkpoint trained on it."""
    root = tmp_path_factory.mktemp("stream")
    ds = rgb_dataset(sim_recordings, root / "ds")
    return ds, train("flow", ds, root / "flow")


def _clip(ds: Path, n: int) -> np.ndarray:
    """n frames of the dataset's slip sequences, one after the other."""
    import vtsbench

    view = vtsbench.load(ds).view("slip")
    return np.concatenate([view[i]["rgb"] for i in range(len(view))])[:n]


def _video(path: Path, frames: np.ndarray) -> Path:
    import cv2

    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 25.0,
                         (frames.shape[2], frames.shape[1]))
    for f in frames:
        vw.write(cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
    vw.release()
    return path


def _lines(text: str) -> list[dict[str, Any]]:
    """Every line parsed and checked against schemas/stream.schema.json."""
    docs = [json.loads(line) for line in text.splitlines()]
    for d in docs:
        assert line_errors(d) == [], (d, line_errors(d))
    assert docs[0]["type"] == "header" and docs[-1]["type"] == "summary"
    assert all(d["type"] == "call" for d in docs[1:-1])
    return docs


def _stream(*args: object) -> Any:
    return CliRunner().invoke(app, ["stream", *map(str, args)])


def test_video_end_to_end_with_annotated_video(flow_run: tuple[Path, Path],
                                               tmp_path: Path) -> None:
    import cv2

    ds, ckpt = flow_run
    video = _video(tmp_path / "take.avi", _clip(ds, 24))
    out = tmp_path / "calls.mp4"
    res = _stream("flow", ckpt, "--source", video, "--video-out", out, "--smoothing", "2")
    assert res.exit_code == 0, res.output
    docs = _lines(res.stdout)
    head, calls, summary = docs[0], docs[1:-1], docs[-1]
    assert head["recipe"] == "flow" and head["window"] == 8 and head["size"] == [96, 128]
    assert head["smoothing"] == {"rule": "debounce", "calls": 2} and head["fps"] == 25.0
    assert len(head["checkpoint_sha256"]) == 64 and head["source"]["kind"] == "video"
    assert [c["frame_index"] for c in calls] == list(range(7, 24))
    assert calls[0]["timestamp_s"] == pytest.approx(7 / 25)
    assert summary["frames"] == summary["processed"] == 24 and summary["dropped"] == 0
    assert summary["calls"] == 17 and summary["end"] == "end of stream"
    assert summary["latency_ms_p95"] >= summary["latency_ms_p50"] > 0
    cap = cv2.VideoCapture(str(out))
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 24
    cap.release()
    assert "24 frames, 0 dropped, 17 calls" in res.stderr
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_episode_source(flow_run: tuple[Path, Path], tmp_path: Path) -> None:
    import vtsbench

    ds, ckpt = flow_run
    frames = _clip(ds, 20)
    with vtsbench.create(tmp_path / "takes", fps=25.0) as w:
        w.add_episode(frames, states=["press"] * 8 + ["slip"] * 12,
                      directions=[None] * 8 + [2] * 12, object="mug", session="s0",
                      slip_onset_s=0.32, episode_id="take-a")
    res = _stream("flow", ckpt, "--source", f"{tmp_path / 'takes'}#take-a")
    assert res.exit_code == 0, res.output
    docs = _lines(res.stdout)
    assert docs[0]["episode"]["slip_onset_s"] == 0.32 and docs[0]["fps"] == 25.0
    assert [d["frame_index"] for d in docs[1:-1]] == list(range(7, 20))
    res2 = _stream("flow", ckpt, "--source", tmp_path / "takes", "--episode", "take-a")
    assert res2.exit_code == 0 and _lines(res2.stdout)[1:-1] == [
        {**d, "latency_ms": d2["latency_ms"]} for d, d2 in zip(docs[1:-1],
                                                                 _lines(res2.stdout)[1:-1],
                                                                 strict=True)]
    bad = _stream("flow", ckpt, "--source", f"{tmp_path / 'takes'}#nope")
    assert bad.exit_code == 2 and "no episode 'nope'" in bad.stderr and bad.stdout == ""


def _one_line_error(res: Any, *words: str) -> list[dict[str, Any]]:
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output and len(res.stderr.strip().splitlines()) == 1
    for w in words:
        assert w in res.stderr, res.stderr
    return _lines(res.stdout) if res.stdout else []


def test_bad_input_is_one_line(flow_run: tuple[Path, Path], tmp_path: Path) -> None:
    ds, ckpt = flow_run
    short = _video(tmp_path / "short.avi", _clip(ds, 5))
    docs = _one_line_error(_stream("flow", ckpt, "--source", short),
                           "ended after 5 frames, fewer than the recipe's window of 8")
    assert docs[-1]["end"] == "error" and docs[-1]["calls"] == 0
    big = _video(tmp_path / "big.avi", np.zeros((10, 120, 160, 3), np.uint8))
    docs = _one_line_error(_stream("flow", ckpt, "--source", big),
                           "frame 0 is 120x160x3 uint8; the checkpoint was trained at 96x128")
    assert docs[-1]["processed"] == 1
    broken = tmp_path / "broken.avi"
    broken.write_bytes(b"RIFF not a video at all" * 10)
    assert _one_line_error(_stream("flow", ckpt, "--source", broken), "broken.avi") == []
    assert _one_line_error(_stream("timesformer", ckpt, "--source", short),
                           "not a timesformer recipe checkpoint") == []
    assert _one_line_error(_stream("flow", ckpt, "--source", "97"), "camera 97") == []
    assert _one_line_error(_stream("flow", ckpt, "--source", ds),
                           "DATASET#EPISODE_ID") == []
    res = _stream("flow", ckpt, "--source", short, "--smoothing", "0")
    assert res.exit_code == 2 and "--smoothing" in res.output


class _Slow:
    """A fake model: `delay` seconds a call, slip on every window; optionally raising on call
    `fail_at` or setting `stop` at call `stop_at`."""

    def __init__(self, delay: float = 0.0, fail_at: int | None = None,
                 stop: threading.Event | None = None, stop_at: int | None = None) -> None:
        self.delay, self.fail_at, self.stop, self.stop_at = delay, fail_at, stop, stop_at
        self.n = 0

    def monitor(self, frames: int = 2) -> Monitor:
        return Monitor(WindowPredictor(self, frames, (6, 8), {"state": ("static", "press",
                                                                        "slip")}))

    def __call__(self, window: np.ndarray) -> dict[str, Any]:
        self.n += 1
        if self.n == self.fail_at:
            raise RuntimeError("the model failed")
        if self.stop is not None and self.n == self.stop_at:
            self.stop.set()
        time.sleep(self.delay)
        return {"state_probs": [0.1, 0.1, 0.8], "direction": 1}


def _source(n: int, *, live: bool = False, period: float = 0.0, bad_at: int | None = None,
            stop_with: Exception | None = None) -> Source:
    """n frames of 6x8 (timestamps k * period), at their pace when live; a frame of another
    size at `bad_at`; `stop_with` raised after the last frame (a camera that stops)."""
    def frames():
        t0 = time.monotonic()
        for k in range(n):
            if live and period:
                time.sleep(max(0.0, t0 + k * period - time.monotonic()))
            yield k, k * period, np.full((5, 8, 3) if k == bad_at else (6, 8, 3), k, np.uint8)
        if stop_with is not None:
            raise stop_with

    return Source("camera" if live else "video", "fake", 1 / period if period else None,
                  frames, live=live)


class _Sink:
    """A binary stream that keeps what was written, each write recorded apart."""

    def __init__(self) -> None:
        self.writes: list[bytes] = []

    def write(self, data: bytes) -> None:
        self.writes.append(data)

    def flush(self) -> None:
        pass

    def text(self) -> str:
        return b"".join(self.writes).decode()


@pytest.mark.parametrize("case", ["model fails", "bad frame", "camera stops"])
def test_lines_stay_valid_after_a_failure_mid_stream(case: str) -> None:
    sink = _Sink()
    model = _Slow(fail_at=5 if case == "model fails" else None)
    src = _source(12, bad_at=9 if case == "bad frame" else None,
                  live=case == "camera stops", period=0.001,
                  stop_with=VtsError("the camera stopped giving frames after 12 frames")
                  if case == "camera stops" else None)
    with pytest.raises((RuntimeError, VtsError)) as e:
        run_stream(model.monitor(), src, LineWriter(sink))
    docs = _lines(sink.text())
    assert all(w.endswith(b"\n") and w.count(b"\n") == 1 for w in sink.writes)  # whole lines
    assert docs[-1]["end"] == "error" and docs[-1]["error"] == str(e.value)
    want = {"model fails": 4, "bad frame": 8, "camera stops": None}[case]
    if want is not None:
        assert docs[-1]["calls"] == len(docs) - 2 == want


def test_a_slow_model_drops_frames_and_counts_them() -> None:
    sink = _Sink()
    summary = run_stream(_Slow(delay=0.03).monitor(), _source(40, live=True, period=0.005),
                         LineWriter(sink))
    docs = _lines(sink.text())
    calls = docs[1:-1]
    assert summary == docs[-1] and summary["frames"] == 40
    assert summary["dropped"] > 10 and summary["processed"] + summary["dropped"] == 40
    assert summary["calls"] == len(calls) and docs[0]["source"]["realtime"] is True
    idx = [c["frame_index"] for c in calls]
    assert idx == sorted(set(idx)) and idx[-1] >= 30  # the newest frame each time


def test_realtime_paces_a_file_and_drops_as_a_camera() -> None:
    fast, paced = _Sink(), _Sink()
    a = run_stream(_Slow(delay=0.02).monitor(), _source(20, period=0.004), LineWriter(fast))
    t0 = time.perf_counter()
    b = run_stream(_Slow(delay=0.02).monitor(), _source(20, period=0.004), LineWriter(paced),
                   realtime=True)
    assert a["dropped"] == 0 and a["calls"] == 19
    assert b["dropped"] > 5 and b["frames"] == 20 and time.perf_counter() - t0 < 2


def test_interrupt_ends_with_a_summary() -> None:
    stop, sink = threading.Event(), _Sink()
    summary = run_stream(_Slow(stop=stop, stop_at=3).monitor(), _source(50), LineWriter(sink),
                         stop=stop)
    assert summary["end"] == "interrupted" and summary["calls"] == 3
    assert _lines(sink.text())[-1] == summary
    capped = run_stream(_Slow().monitor(), _source(50), LineWriter(_Sink()), max_frames=10)
    assert capped["end"] == "max frames" and capped["frames"] == 10 and capped["calls"] == 9


def test_real_gelsight_take_streams_end_to_end(tmp_path: Path) -> None:
    """A real GelSight Mini take (320x240 at 25 fps) through a flow tree fitted on simulated
    frames of its size."""
    from vtsbench.dataset.build import BuildOptions, build
    from vtsbench.sim.simulate import simulate

    take = real_dir("incipient_slip_sample") / "blue_mug" / "exp_num_1" / "camera_0.avi"
    simulate(tmp_path / "rec", seed=1, n_static=3, n_sequences=9, n_presses=0,
             size=(240, 320), progress=False)
    build(tmp_path / "rec", tmp_path / "ds", BuildOptions(depth=False))
    ckpt = train("flow", tmp_path / "ds", tmp_path / "flow")
    res = _stream("flow", ckpt, "--source", take, "--video-out", tmp_path / "take.mp4")
    assert res.exit_code == 0, res.output
    docs = _lines(res.stdout)
    assert docs[-1]["frames"] == 228 and docs[-1]["calls"] == 221
    assert {d["state"] for d in docs[1:-1]} <= {"static", "press", "slip"}
    assert (tmp_path / "take.mp4").stat().st_size > 0
