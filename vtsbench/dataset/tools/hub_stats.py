"""Per-episode statistics of the episodes' hub copy (meta/episodes_stats.jsonl, LeRobot v2.1's
shapes): min, max, mean, std and count of each label column, and of each image per channel (rgb
scaled to [0, 1], depth in mm, contact 0/1) from exact histograms of every pixel."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from .hub_rows import stored_counts

if TYPE_CHECKING:
    import pyarrow as pa



@dataclass
class Moments:
    """Running count, sum, sum of squares, min and max, per channel."""

    count: int = 0
    total: np.ndarray = field(default_factory=lambda: np.zeros(0))
    squares: np.ndarray = field(default_factory=lambda: np.zeros(0))
    low: np.ndarray = field(default_factory=lambda: np.zeros(0))
    high: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @classmethod
    def of(cls, values: np.ndarray) -> Moments:
        """values: (n, channels), float64."""
        return cls(len(values), values.sum(0), np.square(values).sum(0), values.min(0),
                   values.max(0))

    @classmethod
    def of_hist(cls, hist: np.ndarray, values: np.ndarray) -> Moments:
        """From counts per value (channels, values): exact, and far faster than float64
        sums over every pixel."""
        hist = np.asarray(hist, np.int64)
        seen = [values[h > 0] for h in hist]
        return cls(int(hist[0].sum()), hist @ values, hist @ np.square(values),
                   np.array([v.min() for v in seen]), np.array([v.max() for v in seen]))

    def add(self, other: Moments) -> None:
        if not self.count:
            self.count, self.total, self.squares = other.count, other.total, other.squares
            self.low, self.high = other.low, other.high
            return
        self.count += other.count
        self.total, self.squares = self.total + other.total, self.squares + other.squares
        self.low, self.high = np.minimum(self.low, other.low), np.maximum(self.high, other.high)

    def doc(self, count: int, image: bool) -> dict[str, Any]:
        """LeRobot's stats of one feature: min, max, mean, std as lists ((C, 1, 1) for an
        image, (1,) otherwise) and count."""
        mean = self.total / self.count
        std = np.sqrt(np.maximum(self.squares / self.count - np.square(mean), 0.0))

        def shape(v: np.ndarray) -> list[Any]:
            return [[[float(x)]] for x in v] if image else [float(x) for x in v]
        return {"min": shape(self.low), "max": shape(self.high), "mean": shape(mean),
                "std": shape(std), "count": [int(count)]}


def _histogram(frames: np.ndarray, channel: int | None, bins: int) -> np.ndarray:
    """Counts of each value of one channel over frames (n, H, W[, C]) of uint8 or uint16:
    OpenCV's calcHist (a tenth of numpy's bincount), a few frames at a time so that its float32
    counts stay exact."""
    import cv2

    h, w = frames.shape[1:3]
    step = max(1, 2**23 // (h * w))
    out = np.zeros(bins, np.int64)
    for i in range(0, len(frames), step):
        part = np.ascontiguousarray(frames[i:i + step]).reshape(-1, w, *frames.shape[3:])
        got = cv2.calcHist([part], [channel or 0], None, [bins], [0, bins])
        out += np.rint(got.ravel()).astype(np.int64)
    return out


def image_moments(data: dict[str, np.ndarray], scale_mm: float) -> dict[str, Moments]:
    """Moments of a batch of frames, from histograms: rgb per channel scaled to [0, 1] (as
    LeRobot's image stats), depth in mm (the loader's float32 values), contact as 0/1."""
    rgb = data["rgb"]
    hist = np.stack([_histogram(rgb, c, 256) for c in range(3)])
    out = {"rgb": Moments.of_hist(hist, np.arange(256) / 255.0)}
    if "depth" in data:
        counts = stored_counts(data["depth"], scale_mm).view(np.uint16)
        mm = np.arange(2**16, dtype=np.uint16).view(np.int16).astype(np.float32) * np.float32(
            scale_mm)
        out["depth"] = Moments.of_hist(_histogram(counts, None, 2**16)[None],
                                        mm.astype(np.float64))
        on = int(np.count_nonzero(data["contact"]))
        out["contact"] = Moments.of_hist(np.array([[data["contact"].size - on, on]]),
                                          np.array([0.0, 1.0]))
    return out


def label_stats(labels: pa.Table) -> dict[str, Any]:
    """Stats of an episode's label columns (those with numbers; nulls left out, a column of
    nulls alone has none)."""
    import pyarrow as pa

    out = {}
    for name in labels.column_names:
        col = labels.column(name)
        if not (pa.types.is_integer(col.type) or pa.types.is_floating(col.type)
                or pa.types.is_boolean(col.type)):
            continue
        values = np.asarray(col.drop_null().to_numpy(zero_copy_only=False), np.float64)
        if len(values):
            out[name] = Moments.of(values[:, None]).doc(len(values), False)
    return out
