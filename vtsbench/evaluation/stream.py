"""Scoring a stream submission (`vtsbench predict ... --stream`, or `vtsbench stream` runs of
episodes concatenated) against the episodes' per-frame labels: how soon after slip begins it
is called, how often slip is called while the object is held or pressed, slips never called,
and the direction at detection (docs/evaluation.md, "Streams").

- The onset is the episode's `slip_onset_s` (the first frame at or after it); an episode
  without one has no slip.
- A detection is the first call at or after the onset whose reported (smoothed) state is slip
  and stays slip for the next HOLD_CALLS - 1 calls (or to the end): a one-call flicker is not
  a detection. Delay: its time minus the onset's, in ms and in frames. A slip episode without a
  detection is missed (its delay is not in the percentiles).
- A false alarm is a call whose reported state turns into slip (from another state, or the
  first call) on a frame whose truth is static or press, before the onset (a slip episode) or
  anywhere (an episode without slip); they are counted per minute of those frames that were
  called. So a debounce costs delay and saves false alarms, both charged here.
- Direction at detection: the detection call's bin against the episode's slip bin (at the
  onset): exact, and within one bin (the adjacent-direction convention of the slip task).
- Intervals: the seeded bootstrap of evaluation/metrics.py over episodes.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import VtsError
from ..labels import STATES
from . import metrics as M
from .stream_result import STREAM_METRIC_VERSION, EpisodeScore, StreamResult, method_name

if TYPE_CHECKING:
    from .result import EvalResult

#: Calls in a row (from the first) that a detection's slip must last.
HOLD_CALLS = 2
#: The most bytes of a stream submission read.
MAX_BYTES = 1 << 30
SLIP = STATES.index("slip")
_OK = {STATES.index("static"), STATES.index("press")}


@dataclass
class Stream:
    """One episode's lines of a submission: header, calls, summary."""

    header: dict[str, Any]
    calls: list[dict[str, Any]] = field(default_factory=list)
    summary: dict[str, Any] | None = None


def is_stream_submission(path: str | Path) -> bool:
    """Whether a file starts with a stream header line (`vtsbench stream`'s format)."""
    try:
        with open(path, "rb") as fh:
            first = fh.readline(1 << 20)
        doc = json.loads(first)
    except (OSError, ValueError):
        return False
    return isinstance(doc, dict) and doc.get("type") == "header" and \
        doc.get("format") == "vtsbench.stream"


@dataclass(frozen=True)
class StreamSubmission:
    """A stream submission read and checked once: its file as given, its streams and the
    sha256 of its bytes (what scoring, the result and the timeline figure share)."""

    path: str | Path
    streams: list[Stream]
    sha256: str


def read_stream_submission(path: str | Path) -> StreamSubmission:
    """The streams of a submission, every line checked against schemas/stream.schema.json
    (the first problem is one line naming the line number), and its sha256, in one read."""
    from ..recipes.stream import line_errors

    p = Path(path)
    if not p.is_file():
        raise VtsError("stream submission not found", p)
    if p.stat().st_size > MAX_BYTES:
        raise VtsError(f"stream submission larger than {MAX_BYTES >> 20} MiB", p)
    streams: list[Stream] = []
    digest = hashlib.sha256()
    with open(p, "rb") as fh:
        for no, raw in enumerate(fh, 1):
            digest.update(raw)
            try:
                doc = json.loads(raw)
            except ValueError as e:
                raise VtsError(f"line {no} is not JSON ({e.msg})", p) from None
            errs = line_errors(doc)
            if errs:
                raise VtsError(f"line {no}: {errs[0]}", p)
            kind = doc["type"]
            open_ = bool(streams) and streams[-1].summary is None
            if kind == "header":
                if open_:
                    raise VtsError(f"line {no}: a header before the previous stream's summary",
                                   p)
                streams.append(Stream(doc))
            elif not open_:
                raise VtsError(f"line {no}: a {kind} line outside a stream (no header before "
                               "it)", p)
            elif kind == "call":
                streams[-1].calls.append(doc)
            else:
                streams[-1].summary = doc
    if not streams:
        raise VtsError("empty stream submission", p)
    if streams[-1].summary is None:
        raise VtsError("the last stream has no summary line (cut short?)", p)
    return StreamSubmission(path, streams, digest.hexdigest())


def _read(submission: str | Path | StreamSubmission) -> StreamSubmission:
    """A submission as read and checked: the one given, or its file read now."""
    if isinstance(submission, StreamSubmission):
        return submission
    return read_stream_submission(submission)


def _truth(ds: Any, split: str, part: str) -> dict[str, dict[str, Any]]:
    """Per episode of the split part: row, timestamps, states (-1 unknown), directions."""
    eps = ds.episodes.split(split, part)
    rows = eps.index.to_pylist()
    fr = eps.frames
    ei = fr.column("episode_index").to_numpy()
    ts = fr.column("timestamp").to_numpy()
    st = np.asarray(fr.column("state").fill_null(-1).to_numpy(), np.int64)
    di = np.asarray(fr.column("direction").fill_null(-1).to_numpy(), np.int64)
    out = {}
    for r in rows:
        m = ei == r["episode_index"]
        out[r["episode_id"]] = {"row": r, "ts": ts[m], "state": st[m], "direction": di[m]}
    return out


def score_episode(eid: str, truth: Mapping[str, Any], calls: Sequence[Mapping[str, Any]],
                  where: str | Path = "") -> EpisodeScore:
    """One episode's detection, delay, false alarms and direction at detection."""
    ts, st, di = truth["ts"], truth["state"], truth["direction"]
    row, n = truth["row"], len(truth["ts"])
    fps = float(row["fps"])
    rep = np.full(n, -2, np.int64)  # -2: no call at that frame, -1: a call without a state
    dirc = np.full(n, -1, np.int64)
    for c in calls:
        k = int(c["frame_index"])
        if not 0 <= k < n:
            raise VtsError(f"episode {eid}: a call at frame_index {k}; the episode has {n} "
                           f"frames (0..{n - 1})", where)
        rep[k] = -1 if c["state"] is None else STATES.index(c["state"])
        dirc[k] = -1 if c["direction"] is None else int(c["direction"])
    called = np.flatnonzero(rep > -2)
    onset_s = row.get("slip_onset_s")
    onset = None if onset_s is None or onset_s != onset_s else \
        int(np.searchsorted(ts, float(onset_s) - 1e-6))
    detection = None
    if onset is not None:
        after = called[called >= onset]
        for j, f in enumerate(after):
            nxt = after[j:j + HOLD_CALLS]
            if (rep[nxt] == SLIP).all():
                detection = int(f)
                break
    end = n if onset is None else onset
    region = np.zeros(n, bool)
    region[:end] = np.isin(st[:end], list(_OK))
    region &= rep > -2
    fa = 0
    prev = None
    for f in called:
        is_slip = rep[f] == SLIP
        if region[f] and is_slip and prev is not True:
            fa += 1
        prev = bool(is_slip)
    dtrue = None
    if onset is not None:
        later = di[onset:][di[onset:] >= 0]
        dtrue = int(later[0]) if len(later) else None
    return EpisodeScore(
        eid, str(row["object"]), onset is not None, onset, detection,
        None if detection is None else detection - onset,
        None if detection is None else round(1000.0 * float(ts[detection] - ts[onset]), 3),
        dtrue, None if detection is None or dirc[detection] < 0 else int(dirc[detection]),
        fa, round(float(region.sum()) / fps, 6), len(called))


def _pct(v: np.ndarray, q: float) -> float:
    return float(np.percentile(v, q)) if len(v) else M.NAN


def aggregate(scores: Sequence[EpisodeScore], headers: Sequence[Mapping[str, Any]],
              summaries: Sequence[Mapping[str, Any]], seed: int = 0) -> StreamResult:
    """The stream figures over episodes, with bootstrap intervals over episodes."""
    slip = [s for s in scores if s.slip]
    det = np.array([s.detection_frame is not None for s in slip], bool)
    dms = np.array([np.nan if s.delay_ms is None else s.delay_ms for s in slip])
    dfr = np.array([np.nan if s.delay_frames is None else s.delay_frames for s in slip])
    idx = M.bootstrap_indices(len(slip), seed=seed)

    def boot(fn: Any) -> list[float]:
        if len(slip) <= 1:
            v = fn(np.arange(len(slip)))
            return [v, v]
        return M.interval(np.array([fn(i) for i in idx]))

    def p(q: float) -> Any:
        return lambda i: _pct(dms[i][det[i]], q)

    fa = np.array([s.false_alarms for s in scores], float)
    ns = np.array([s.non_slip_s for s in scores], float)
    with np.errstate(invalid="ignore", divide="ignore"):
        rate = float(fa.sum() / (ns.sum() / 60.0)) if ns.sum() > 0 else M.NAN
        ia = M.bootstrap_indices(len(scores), seed=seed)
        rates = fa[ia].sum(1) / (ns[ia].sum(1) / 60.0)
    hit = [s for s in slip if s.detection_frame is not None and s.direction_true is not None]
    ok = np.array([s.direction_called == s.direction_true for s in hit], float)
    near = np.array([s.direction_called is not None and int(M.bin_distance(
        s.direction_true, s.direction_called)) <= 1 for s in hit], float)
    ih = M.bootstrap_indices(len(hit), seed=seed)
    procs = sum(int(s["processed"]) for s in summaries)
    wall = sum(float(s["wall_s"]) for s in summaries)
    p95 = [s["latency_ms_p95"] for s in summaries if s["latency_ms_p95"] is not None]
    h = headers[0]
    sr = StreamResult(
        STREAM_METRIC_VERSION, str(h["recipe"]), h.get("checkpoint_sha256"),
        int(h["smoothing"]["calls"]), int(h["window"]), len(scores), len(slip), int(det.sum()),
        float(1.0 - det.mean()) if len(slip) else M.NAN,
        tuple(boot(lambda i: float(1.0 - det[i].mean()))),
        _pct(dms[det], 50), tuple(boot(p(50))), _pct(dms[det], 90), tuple(boot(p(90))),
        _pct(dfr[det], 50), _pct(dfr[det], 90), int(fa.sum()), round(float(ns.sum()) / 60.0, 6),
        rate, tuple(M.interval(rates)) if len(scores) > 1 else (rate, rate),
        float(ok.mean()) if len(hit) else M.NAN,
        tuple(M.interval(ok[ih].mean(1))) if len(hit) > 1 else
        ((float(ok.mean()),) * 2 if len(hit) else (M.NAN, M.NAN)),
        float(near.mean()) if len(hit) else M.NAN,
        round(procs / wall, 3) if wall > 0 else M.NAN,
        float(np.median(p95)) if p95 else M.NAN, tuple(scores))
    return StreamResult.from_dict(sr.to_dict())  # NaN (undefined) as None, as in metrics.json


def score_streams(submission: str | Path | StreamSubmission, ds: Any, split: str, part: str
                  ) -> StreamResult:
    """Score a stream submission (its file, read and checked here, or one already read) on a
    split part of a dataset's episodes: an episode of the part missing, one not in it, one
    twice, streams of several recipes or smoothings, a stream that ended in an error or a call
    outside its episode are each one line."""
    sub = _read(submission)
    streams, path = sub.streams, sub.path
    truth = _truth(ds, split, part)
    seen: dict[str, Stream] = {}
    for s in streams:
        ep = s.header.get("episode") or {}
        eid = ep.get("episode_id")
        if not isinstance(eid, str):
            raise VtsError("a stream whose header names no episode (stream a dataset "
                           "episode: vtsbench predict --stream)", path)
        if eid not in truth:
            raise VtsError(f"episode {eid!r:.80} is not in {split}/{part} ({len(truth)} "
                           "episodes)", path)
        if eid in seen:
            raise VtsError(f"episode {eid!r:.80} is streamed twice", path)
        assert s.summary is not None
        if s.summary["end"] != "end of stream":
            raise VtsError(f"episode {eid}: its stream ended with {s.summary['end']!r}"
                           + (f" ({s.summary['error']})" if s.summary["error"] else "")
                           + ": stream every frame of every episode", path)
        seen[eid] = s
    missing = [e for e in truth if e not in seen]
    if missing:
        raise VtsError(f"{len(missing)} of the {len(truth)} episodes of {split}/{part} are "
                       f"missing from the submission (first: {missing[0]})", path)
    first = streams[0].header
    for s in streams[1:]:
        for key in ("recipe", "checkpoint_sha256", "smoothing", "window"):
            if s.header.get(key) != first.get(key):
                raise VtsError(f"the streams differ in {key} ({first.get(key)!r:.60} and "
                               f"{s.header.get(key)!r:.60}): a submission is one method", path)
    scores = [score_episode(e, truth[e], seen[e].calls, path) for e in truth]
    summaries = [seen[e].summary for e in truth]
    return aggregate(scores, [first], [s for s in summaries if s is not None])


def stream_result(submission: str | Path | StreamSubmission, dataset: Any, split: str,
                  part: str, version: str = "0+unknown") -> EvalResult:
    """A stream submission (its file, or one already read) scored, as an EvalResult (kind
    "episode", no window tasks; `version`: vtsbench's)."""
    from .result import DatasetRef, EvalResult, SubmissionRef
    from .submission import open_dataset

    ds = open_dataset(dataset)
    sub = _read(submission)
    sr = score_streams(sub, ds, split, part)
    info = ds.info
    return EvalResult(M.METRIC_VERSION, version,
                      DatasetRef(info.name, info.dataset_version, info.dataset_sha256),
                      split, part, "episode", sr.n_episodes,
                      SubmissionRef(Path(sub.path).name, sub.sha256, method_name(sr),
                                    sr.recipe, (0,)),
                      {}, stream=sr)


def write_stream_figure(result: EvalResult, ds: Any, submission: str | Path | StreamSubmission,
                        out: Path, most: int = 8) -> str:
    """stream_timeline.png: per episode (slip ones first, at most `most`), the true state and
    the reported state over time, the onset and the detection marked (`submission`: the one
    scored, as read for `stream_result`, or its file)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.colors import ListedColormap
    from matplotlib.figure import Figure

    from ..figures import MIN_FONT_PT as FONT
    from ..figures import print_style, save_png

    sr = result.stream
    assert sr is not None
    truth = _truth(ds, result.split, result.part)
    calls = {s.header["episode"]["episode_id"]: s.calls for s in _read(submission).streams}
    eps = sorted(sr.episodes, key=lambda e: (not e.slip, e.episode_id))[:most]
    cmap = ListedColormap(["white", "#ffe599", "#d9d9d9", "#6fa8dc", "#e06666"])  # no call,
    # unknown, static, press, slip: codes 0..4
    with print_style():
        fig = Figure(figsize=(8.0, 0.9 * len(eps) + 1.2))
        FigureCanvasAgg(fig)
        fig.suptitle(f"{method_name(sr)}: true state (upper band) and calls (lower)",
                     fontsize=FONT + 1)
        for i, e in enumerate(eps):
            ax = fig.add_subplot(len(eps), 1, i + 1)
            t = truth[e.episode_id]
            ts = t["ts"]
            true = t["state"] + 2
            rep = np.zeros(len(ts), np.int64)
            for c in calls[e.episode_id]:
                rep[c["frame_index"]] = 1 if c["state"] is None else STATES.index(c["state"]) + 2
            dt = 1.0 / float(t["row"]["fps"])
            ax.imshow(np.stack([true, rep]), aspect="auto", cmap=cmap, vmin=0, vmax=4,
                      interpolation="nearest", extent=(0, ts[-1] + dt, 2, 0))
            if e.onset_frame is not None:
                ax.axvline(ts[e.onset_frame], color="black", lw=1.2)
            if e.detection_frame is not None:
                ax.plot([ts[e.detection_frame]], [1.5], marker="v", color="black", ms=6)
            ax.set_yticks([0.5, 1.5], ["truth", "calls"], fontsize=FONT)
            ax.set_ylabel(e.episode_id.replace("episode-", "ep "), fontsize=FONT, rotation=0,
                          ha="right", va="center")
            if i < len(eps) - 1:
                ax.set_xticks([])
        ax.set_xlabel("time (s); grey static, blue press, red slip, yellow unknown, white no "
                      "call; line: onset, triangle: detection", fontsize=FONT)
        fig.subplots_adjust(left=0.16, right=0.98, top=0.9, bottom=0.12, hspace=0.35)
        name = "stream_timeline.png"
        save_png(fig, out / name)
    return name
