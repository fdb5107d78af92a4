"""The scores of a stream submission as typed records (`StreamResult`, one `EpisodeScore` per
episode; schemas/stream_metrics.schema.json) and their text: the printed line and the report's
section. The definitions are evaluation/stream.py's."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from . import metrics as M

#: Version of the stream metric definitions (stored with every stream result).
STREAM_METRIC_VERSION = "1.0"

Interval = tuple[float | None, float | None]


@dataclass(frozen=True)
class EpisodeScore:
    """One episode's figures."""

    episode_id: str
    object: str
    slip: bool
    onset_frame: int | None
    detection_frame: int | None
    delay_frames: int | None
    delay_ms: float | None
    direction_true: int | None
    direction_called: int | None
    false_alarms: int
    non_slip_s: float
    calls: int

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


@dataclass(frozen=True)
class StreamResult:
    """A stream submission's scores (schemas/stream_metrics.schema.json)."""

    metric_version: str
    recipe: str
    checkpoint_sha256: str | None
    smoothing: int
    window: int
    n_episodes: int
    n_slip_episodes: int
    detected: int
    missed: float | None
    missed_ci95: Interval
    delay_ms_p50: float | None
    delay_ms_p50_ci95: Interval
    delay_ms_p90: float | None
    delay_ms_p90_ci95: Interval
    delay_frames_p50: float | None
    delay_frames_p90: float | None
    false_alarms: int
    non_slip_minutes: float
    false_alarms_per_min: float | None
    false_alarms_per_min_ci95: Interval
    direction_accuracy: float | None
    direction_accuracy_ci95: Interval
    direction_within_one_bin: float | None
    fps_sustained: float | None
    latency_ms_p95: float | None
    episodes: tuple[EpisodeScore, ...] = field(default=())

    def to_dict(self) -> dict[str, Any]:
        d = {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.__dict__.items()}
        d["episodes"] = [e.to_dict() for e in self.episodes]
        return M.jsonable(d)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> StreamResult:
        kw = {k: (tuple(v) if k.endswith("_ci95") else v) for k, v in d.items()}
        kw["episodes"] = tuple(EpisodeScore(**e) for e in d["episodes"])
        return cls(**kw)


def method_name(sr: StreamResult) -> str:
    """The method a stream result is listed as: the recipe and its decision rule."""
    return f"{sr.recipe} (debounce {sr.smoothing})"


def _ms(v: float | None) -> str:
    return "-" if v is None else f"{v:.0f}"


def _ci(ci: Interval, scale: float = 1.0, digits: int = 0) -> str:
    if ci[0] is None or ci[1] is None:
        return "-"
    return f"[{ci[0] * scale:.{digits}f}, {ci[1] * scale:.{digits}f}]"


def stream_line(sr: StreamResult) -> str:
    """One printed line of the stream figures."""
    def pct(v: float | None) -> str:
        return "-" if v is None else f"{100 * v:.1f} %"

    fa = "-" if sr.false_alarms_per_min is None else f"{sr.false_alarms_per_min:.2f}"
    return (f"stream: delay p50 {_ms(sr.delay_ms_p50)} ms, p90 {_ms(sr.delay_ms_p90)} ms "
            f"({sr.detected} of {sr.n_slip_episodes} slips caught, missed "
            f"{pct(sr.missed)}); false alarms {fa} per min; direction at detection "
            f"{pct(sr.direction_accuracy)}")


def stream_markdown(sr: StreamResult) -> list[str]:
    """The stream section of report.md: the table of figures and one row per episode."""
    def pct(v: float | None) -> str:
        return "-" if v is None else f"{100 * v:.1f}"

    def num(v: float | None, d: int = 2) -> str:
        return "-" if v is None else f"{v:.{d}f}"

    lines = ["## Streams: how fast slip is caught", "",
             f"{sr.recipe}, window {sr.window}, debounce {sr.smoothing}; {sr.n_episodes} "
             f"episodes ({sr.n_slip_episodes} with slip); stream metric version "
             f"{sr.metric_version}. Intervals: bootstrap 95 % over episodes.", "",
             "| figure | value | 95 % CI |", "|---|---:|---|",
             f"| detection delay p50 (ms) | {_ms(sr.delay_ms_p50)} | "
             f"{_ci(sr.delay_ms_p50_ci95)} |",
             f"| detection delay p90 (ms) | {_ms(sr.delay_ms_p90)} | "
             f"{_ci(sr.delay_ms_p90_ci95)} |",
             f"| detection delay p50 / p90 (frames) | {num(sr.delay_frames_p50, 1)} / "
             f"{num(sr.delay_frames_p90, 1)} | |",
             f"| missed slips % | {pct(sr.missed)} | {_ci(sr.missed_ci95, 100, 1)} |",
             f"| false alarms per minute of static and press | "
             f"{num(sr.false_alarms_per_min)} ({sr.false_alarms} in "
             f"{sr.non_slip_minutes:.2f} min) | {_ci(sr.false_alarms_per_min_ci95, 1, 2)} |",
             f"| direction at detection % | {pct(sr.direction_accuracy)} | "
             f"{_ci(sr.direction_accuracy_ci95, 100, 1)} |",
             f"| direction within one bin % | {pct(sr.direction_within_one_bin)} | |",
             f"| frames per second sustained | {num(sr.fps_sustained, 1)} | |",
             f"| latency p95 (ms, median over episodes) | {num(sr.latency_ms_p95, 1)} | |",
             "", "| episode | object | onset frame | detected at | delay ms | direction "
             "true / called | false alarms |", "|---|---|---:|---:|---:|---|---:|"]
    for e in sr.episodes:
        lines.append(f"| {e.episode_id} | {e.object} | {e.onset_frame if e.slip else '-'} | "
                     f"{'-' if e.detection_frame is None else e.detection_frame} | "
                     f"{_ms(e.delay_ms)} | {'-' if e.direction_true is None else e.direction_true}"
                     f" / {'-' if e.direction_called is None else e.direction_called} | "
                     f"{e.false_alarms} |")
    return lines
