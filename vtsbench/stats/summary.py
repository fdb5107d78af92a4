"""Per-window statistics summarised per folder (medians and quartiles, shares), and the JSON
file `vtsbench stats --out` writes (schemas/stats.schema.json)."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .folder import Window
from .window import SETTINGS, WindowStats

FORMAT = "vtsbench.stats"
FORMAT_VERSION = "1.0"

#: Summarised statistics: name -> (label, unit). Motion ones are defined on moving windows.
DISTRIBUTIONS: dict[str, tuple[str, str]] = {
    "displacement_px": ("median displacement, first to last frame", "px"),
    "translation_r2": ("one translation fits the displacement field (R², 1 = rigid shift)", ""),
    "co_moving_share": ("share of the contact moving with the median motion", ""),
    "strain_ratio": ("strain relative to translation", ""),
    "rotation_deg": ("rotation a window", "deg"),
    "largest_step_share": ("share of the motion in the largest frame step", ""),
    "speed_cv": ("speed variation over the steps (CV)", ""),
    "imprint_hp_rms": ("imprint texture, high-pass RMS", "DN"),
    "off_contact_hp_rms": ("high-pass RMS off the contact", "DN"),
    "temporal_noise": ("temporal noise off the contact", "DN"),
}
#: Yes/no statistics summarised as the share of windows where they hold.
SHARES: dict[str, tuple[str, str]] = {
    "phase_miss": ("phase correlation returns under 0.5 px although the gel moves", ""),
    "contact_change": ("moving windows in which contact is made or lost", ""),
}


@dataclass(frozen=True)
class Distribution:
    """Median and quartiles of a statistic over the n windows where it is defined."""

    n: int
    median: float | None
    q25: float | None
    q75: float | None


@dataclass(frozen=True)
class Share:
    """The share of the n windows where a yes/no statistic holds."""

    n: int
    share: float | None


@dataclass
class FolderStats:
    """One folder's statistics."""

    folder: str
    n_windows: int
    n_sampled: int
    n_contact: int
    n_moving: int
    n_static: int
    frames_per_window: int
    distributions: dict[str, Distribution]
    shares: dict[str, Share]
    windows: list[dict[str, Any]] = field(default_factory=list)


def distribution(values: list[float]) -> Distribution:
    """Median and quartiles (numpy's linear interpolation); None for no values."""
    if not values:
        return Distribution(0, None, None, None)
    q25, med, q75 = np.percentile(np.asarray(values, np.float64), [25, 50, 75])
    return Distribution(len(values), float(med), float(q25), float(q75))


def summarise(folder: Path, windows: list[Window], n_windows: int, stats: list[WindowStats]
              ) -> FolderStats:
    """The folder's summary of the sampled windows' statistics."""
    moving = [s for s in stats if s.moving]
    dists = {}
    for name in DISTRIBUTIONS:
        pool = moving if name not in {"imprint_hp_rms", "off_contact_hp_rms",
                                      "temporal_noise"} else stats
        dists[name] = distribution([v for s in pool if (v := getattr(s, name)) is not None
                                     and np.isfinite(v)])
    shares = {}
    for name in SHARES:
        flags = [v for s in moving if (v := getattr(s, name)) is not None]
        shares[name] = Share(len(flags), float(np.mean(flags)) if flags else None)
    frames = [s.frames for s in stats]
    return FolderStats(
        folder=str(folder), n_windows=n_windows, n_sampled=len(stats),
        n_contact=sum(s.contact for s in stats), n_moving=len(moving),
        n_static=len(stats) - len(moving),
        frames_per_window=int(np.bincount(frames).argmax()) if frames else 0,
        distributions=dists, shares=shares,
        windows=[{"entry": w.entry, "start": w.start, "stop": w.stop, **_finite(asdict(s))}
                 for w, s in zip(windows, stats, strict=True)])


def _finite(d: dict[str, Any]) -> dict[str, Any]:
    """None for a non-finite number (JSON has none)."""
    return {k: None if isinstance(v, float) and not np.isfinite(v) else v for k, v in d.items()}


def report_doc(folders: list[FolderStats]) -> dict[str, Any]:
    """The JSON document of one or more folders' statistics."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        ver = version("vtsbench")
    except PackageNotFoundError:
        ver = "unknown"
    return {"format": FORMAT, "format_version": FORMAT_VERSION, "vtsbench_version": ver,
            "settings": dict(SETTINGS), "folders": [asdict(f) for f in folders]}


def write_report(path: Path, folders: list[FolderStats]) -> None:
    """Write the statistics as JSON, atomically."""
    from ..atomic import write_text_atomic

    text = json.dumps(report_doc(folders), indent=1, allow_nan=False) + "\n"
    write_text_atomic(path, text)
