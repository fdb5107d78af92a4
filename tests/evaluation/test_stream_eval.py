"""Scoring stream submissions: detection delay, misses, false alarms and direction at detection
on hand-made calls of known answers (a call exactly at the onset, a flicker, a debounce, an
episode without slip, adjacent bins), the refusals in one line, and `vtsbench eval` /
the leaderboard on a stream submission."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

import vtsbench
from tests.fixtures.spy import record_calls
from vtsbench.cli import app
from vtsbench.errors import VtsError
from vtsbench.evaluation.result import EvalResult
from vtsbench.evaluation.stream import (
    StreamResult,
    aggregate,
    is_stream_submission,
    score_episode,
    score_streams,
)
from vtsbench.jsonio import strict_validator
from vtsbench.labels import STATES
from vtsbench.recipes.stream import line_errors

FPS = 25.0
SCHEMAS = Path(__file__).resolve().parents[2] / "schemas"


def _truth(states: str, onset: int | None, direction: int = 2) -> dict[str, Any]:
    """An episode's truth from one letter a frame: s static, p press, S slip, - unknown."""
    code = {"s": 0, "p": 1, "S": 2, "-": -1}
    st = np.array([code[c] for c in states])
    return {"row": {"fps": FPS, "object": "mug", "slip_onset_s": None if onset is None
                    else onset / FPS},
            "ts": np.arange(len(states)) / FPS, "state": st,
            "direction": np.where(st == 2, direction, -1)}


def _calls(states: str, first: int = 0, direction: int | None = 2) -> list[dict[str, Any]]:
    """Calls from frame `first` on, one letter a frame (s, p, S, or . for no state)."""
    name = {"s": "static", "p": "press", "S": "slip", ".": None}
    return [{"frame_index": first + i, "state": name[c],
             "direction": direction if c == "S" else None} for i, c in enumerate(states)]


def test_a_call_exactly_at_the_onset() -> None:
    t = _truth("ssssppppSSSSSSSS", 8)
    e = score_episode("e", t, _calls("ssppppSSSSSSSS", 2))
    assert (e.onset_frame, e.detection_frame, e.delay_frames, e.delay_ms) == (8, 8, 0, 0.0)
    assert e.false_alarms == 0 and e.non_slip_s == pytest.approx(6 / FPS)
    assert e.direction_true == e.direction_called == 2


def test_raw_against_debounced() -> None:
    t = _truth("sssssssssSSSSSSSSSS", 9)
    raw = score_episode("e", t, _calls("ssSssssSSSSSSSSSS", 2))  # a flicker at frame 4
    deb = score_episode("e", t, _calls("sssssssssssSSSSSS", 2))  # debounced: slip from 13
    assert raw.false_alarms == 1 and raw.delay_frames == 0
    assert deb.false_alarms == 0 and deb.detection_frame == 13 and deb.delay_frames == 4
    assert deb.delay_ms == pytest.approx(160.0)


def test_a_one_call_flicker_after_the_onset_is_not_a_detection() -> None:
    t = _truth("ssssSSSSSSSS", 4)
    e = score_episode("e", t, _calls("sSsSSSSS", 4))
    assert e.detection_frame == 7 and e.delay_frames == 3
    last = score_episode("e", t, _calls("sssssssS", 4))  # slip on the last call only: holds
    assert last.detection_frame == 11


def test_missed_and_an_episode_without_slip() -> None:
    miss = score_episode("m", _truth("ssssSSSS", 4), _calls("ssssssss"))
    assert miss.detection_frame is None and miss.delay_ms is None and miss.slip
    still = score_episode("n", _truth("sssspppppsss----", None),
                          _calls("sSSSsppSppss....", 0))
    assert not still.slip and still.onset_frame is None
    assert still.false_alarms == 2  # two turns into slip; a run of slip counts once
    assert still.non_slip_s == pytest.approx(12 / FPS)  # unknown frames are not counted


def test_aggregate_figures_and_adjacent_bins() -> None:
    eps = [score_episode(f"e{i}", _truth("s" * 10 + "S" * 20, 10, direction=0),
                         _calls("s" * (10 + d) + "S" * (20 - d), 0, direction=called))
           for i, (d, called) in enumerate([(0, 0), (2, 7), (4, 4), (6, 0)])]
    eps.append(score_episode("m", _truth("s" * 10 + "S" * 20, 10), _calls("s" * 30)))
    eps.append(score_episode("n", _truth("s" * 30, None), _calls("s" * 5 + "S" * 3 + "s" * 22)))
    head = {"recipe": "x", "checkpoint_sha256": None, "smoothing": {"calls": 1}, "window": 8}
    summ = {"processed": 100, "wall_s": 2.0, "latency_ms_p95": 3.0}
    sr = aggregate(eps, [head], [summ])
    assert sr.n_slip_episodes == 5 and sr.detected == 4 and sr.missed == pytest.approx(0.2)
    delays_ms = np.array([0, 2, 4, 6]) * 40.0
    assert sr.delay_ms_p50 == pytest.approx(np.percentile(delays_ms, 50))
    assert sr.delay_ms_p90 == pytest.approx(np.percentile(delays_ms, 90))
    assert sr.delay_frames_p50 == pytest.approx(3.0)
    assert sr.false_alarms == 1
    assert sr.non_slip_minutes == pytest.approx((5 * 10 + 30) / FPS / 60, abs=1e-6)
    assert sr.false_alarms_per_min == pytest.approx(1 / ((5 * 10 + 30) / FPS / 60))
    assert sr.direction_accuracy == pytest.approx(0.5)  # 0 and 0 right; 7 and 4 wrong
    assert sr.direction_within_one_bin == pytest.approx(0.75)  # 7 is next to 0
    assert sr.fps_sustained == pytest.approx(50.0)
    lo, hi = sr.delay_ms_p50_ci95
    assert lo is not None and hi is not None and lo <= sr.delay_ms_p50 <= hi
    doc = sr.to_dict()
    errors = list(strict_validator(json.loads(
        (SCHEMAS / "stream_metrics.schema.json").read_text())).iter_errors(doc))
    assert not errors, errors[0].message
    assert StreamResult.from_dict(doc).to_dict() == doc


# -- submissions on a dataset ----------------------------------------------------------------

TAKES = {  # object: (states, onset)
    "mug": [("sssssppppSSSSSSSSSSS", 9), ("ssssssssssssssss----", None)],
    "box": [("ssssspppppSSSSSSSSSS", 10), ("sssssssssssSSSSSSSSS", 11)],
}


@pytest.fixture(scope="module")
def takes(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[str]]:
    """Four takes of two objects; returns the dataset and the test part's episode ids."""
    out = tmp_path_factory.mktemp("takes") / "ds"
    code = {"s": "static", "p": "press", "S": "slip", "-": None}
    rng = np.random.default_rng(0)
    with vtsbench.create(out, fps=FPS) as w:
        for obj, eps in TAKES.items():
            for k, (states, onset) in enumerate(eps):
                n = len(states)
                w.add_episode(rng.integers(0, 255, (n, 16, 16, 3), dtype=np.uint8),
                              states=[code[c] for c in states],
                              directions=[3 if c == "S" else None for c in states],
                              object=obj, session=f"s{k}",
                              slip_onset_s=None if onset is None else onset / FPS)
    ds = vtsbench.load(out)
    return out, ds.episodes.split("unseen_objects", "test").ids


def _stream(eid: str, calls: list[dict[str, Any]], n: int, k: int = 1,
            recipe: str = "flow") -> list[dict[str, Any]]:
    head = {"type": "header", "format": "vtsbench.stream", "format_version": 1,
            "recipe": recipe, "checkpoint": "c.safetensors", "checkpoint_sha256": None,
            "source": {"kind": "episode", "name": f"ds#{eid}", "fps": FPS, "realtime": False},
            "episode": {"episode_id": eid, "object": "x", "session": "s0", "sensor": "s",
                        "length": n, "slip_onset_s": None},
            "fps": FPS, "window": 4, "size": None, "smoothing": {"rule": "debounce", "calls": k},
            "classes": {"state": list(STATES)}}
    lines = [head]
    for c in calls:
        lines.append({"type": "call", "frame_index": c["frame_index"],
                      "timestamp_s": c["frame_index"] / FPS, "state": c["state"],
                      "raw_state": c["state"], "direction": c["direction"], "object": None,
                      "confidences": {}, "latency_ms": 1.5})
    lines.append({"type": "summary", "frames": n, "processed": n, "calls": len(calls),
                  "dropped": 0, "wall_s": 0.1, "fps_sustained": n / 0.1,
                  "latency_ms_p50": 1.5, "latency_ms_p95": 1.5, "end": "end of stream",
                  "error": None})
    for line in lines:
        assert not line_errors(line), line_errors(line)
    return lines


def _write(path: Path, streams: list[list[dict[str, Any]]]) -> Path:
    path.write_text("".join(json.dumps(d) + "\n" for s in streams for d in s))
    return path


def _perfect(ds: Path, eid: str) -> list[dict[str, Any]]:
    """Calls that say the truth from frame 3 on (window 4)."""
    e = vtsbench.load(ds).episodes.where(episode_id=eid)[0]
    name = {-1: None, 0: "static", 1: "press", 2: "slip"}
    calls = [{"frame_index": i, "state": name[int(e["state"][i])],
              "direction": 3 if int(e["state"][i]) == 2 else None}
             for i in range(3, len(e["state"]))]
    return _stream(eid, calls, len(e["state"]))


def test_eval_and_leaderboard_of_a_stream_submission(takes: tuple[Path, list[str]],
                                                      tmp_path: Path) -> None:
    ds, ids = takes
    sub = _write(tmp_path / "sub.jsonl", [_perfect(ds, e) for e in ids])
    assert is_stream_submission(sub) and not is_stream_submission(ds / "meta" / "info.json")
    out = tmp_path / "ev"
    res = CliRunner().invoke(app, ["eval", str(sub), "--dataset", str(ds), "--split",
                                   "unseen_objects", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "delay p50 0 ms" in res.output and "missed 0.0 %" in res.output
    doc = json.loads((out / "metrics.json").read_text())
    assert doc["kind"] == "episode" and doc["tasks"] == {}
    errors = list(strict_validator(json.loads((SCHEMAS / "metrics.schema.json").read_text()))
                  .iter_errors(doc))
    assert not errors, errors[0].message
    assert EvalResult.from_dict(doc).to_dict() == doc
    sr = doc["stream"]
    assert sr["false_alarms"] == 0 and sr["direction_accuracy"] == 1.0
    report = (out / "report.md").read_text()
    assert "## Streams: how fast slip is caught" in report and "stream_timeline.png" in report
    assert (out / "stream_timeline.png").stat().st_size > 1000
    root = tmp_path / "boards"
    res = CliRunner().invoke(app, ["leaderboard", "add", str(sub), "--dataset", str(ds),
                                   "--split", "unseen_objects", "--root", str(root)])
    assert res.exit_code == 0, res.output
    board = next(root.glob("*/unseen_objects/leaderboard.md")).read_text()
    assert "| flow (debounce 1) | flow | 1 |" in board and "false alarms / min" in board


def test_refusals_are_one_line(takes: tuple[Path, list[str]], tmp_path: Path) -> None:
    ds, ids = takes
    good = [_perfect(ds, e) for e in ids]

    def refused(streams: list[list[dict[str, Any]]], match: str) -> None:
        with pytest.raises(VtsError, match=match) as e:
            score_streams(_write(tmp_path / "s.jsonl", streams), vtsbench.load(ds),
                          "unseen_objects", "test")
        assert "\n" not in str(e.value)

    refused(good[:-1], "missing from the submission")
    refused(good + good[:1], "streamed twice")
    bad = [dict(d) for d in good[0]]
    bad[1] = {**bad[1], "frame_index": 500}
    refused([bad, *good[1:]], "frame_index 500")
    other = json.loads(json.dumps(good[-1]))
    other[0]["recipe"] = "resnet"
    refused([*good[:-1], other], "differ in recipe")
    refused([good[0][:-1], *good[1:]], "header before the previous stream's summary")
    cut = json.loads(json.dumps(good[0]))
    cut[-1]["end"], cut[-1]["error"] = "error", "the camera stopped"
    refused([cut, *good[1:]], "ended with 'error'")
    (tmp_path / "j.jsonl").write_text(json.dumps(good[0][0]) + "\n{not json\n")
    with pytest.raises(VtsError, match="line 2 is not JSON"):
        score_streams(tmp_path / "j.jsonl", vtsbench.load(ds), "unseen_objects", "test")


def test_eval_reads_and_checks_a_stream_submission_once(takes: tuple[Path, list[str]],
                                                        tmp_path: Path,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """Scores, the submission's sha256 and the timeline figure come from one read."""
    import hashlib

    import vtsbench.evaluation.stream as stream
    from vtsbench.evaluation.report import evaluate_submission

    ds, ids = takes
    sub = _write(tmp_path / "sub.jsonl", [_perfect(ds, e) for e in ids])
    reads = record_calls(monkeypatch, stream, "read_stream_submission")
    res, _, _ = evaluate_submission(sub, ds, "unseen_objects", "test", tmp_path / "ev")
    assert reads == [((sub,), {})]
    assert (tmp_path / "ev" / "stream_timeline.png").is_file()
    assert res.submission.sha256 == hashlib.sha256(sub.read_bytes()).hexdigest()
    assert res.submission.file == "sub.jsonl"
