"""Motion logs: the stage or robot displacement recorded alongside a capture.

A motion log is a CSV file with a header row naming at least the columns `t_s,x_mm,y_mm,z_mm`
(any order; further columns are ignored): time in seconds, then the stage/robot displacement in
mm, with z the indentation (positive into the gel). Times must strictly increase. Between rows the
log is interpolated linearly; outside its time range it says nothing.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import VtsError

COLUMNS: tuple[str, ...] = ("t_s", "x_mm", "y_mm", "z_mm")
#: Slack (s) at the ends of the log's time range, so that a frame time computed as i / fps lands
#: inside a log whose last row was written at exactly that time.
TIME_SLACK_S = 1e-9


@dataclass(frozen=True)
class MotionLog:
    """A motion log: strictly increasing times `t` (s) and displacements `x`, `y`, `z` (mm)."""

    path: str
    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    z: np.ndarray

    @property
    def span(self) -> tuple[float, float]:
        """First and last time of the log (s)."""
        return float(self.t[0]), float(self.t[-1])

    def covers(self, t: float) -> bool:
        """Whether time t (s) lies inside the log's time range."""
        t0, t1 = self.span
        return t0 - TIME_SLACK_S <= t <= t1 + TIME_SLACK_S

    def at(self, t: float) -> tuple[float, float, float] | None:
        """Displacement (x, y, z) in mm at time t, interpolated linearly; None outside the log."""
        if not self.covers(t):
            return None
        return (float(np.interp(t, self.t, self.x)), float(np.interp(t, self.t, self.y)),
                float(np.interp(t, self.t, self.z)))


def read_motion_log(path: str | Path) -> MotionLog:
    """Read and check a motion log CSV; every problem is a one-line VtsError naming the file."""
    path = Path(path)
    from ..jsonio import read_bytes

    data = read_bytes(path, "motion log", 1 << 30)
    try:
        text = data.decode("utf-8-sig")
        rows = [(n, r) for n, r in enumerate(csv.reader(text.splitlines()), start=1)
                if r and any(c.strip() for c in r)]
    except UnicodeDecodeError as e:
        raise VtsError(f"motion log is not UTF-8 text ({e.reason})", path) from None
    except csv.Error as e:
        raise VtsError(f"unreadable motion log ({e})", path) from None
    if not rows:
        raise VtsError(f"motion log is empty (expected a header {','.join(COLUMNS)})", path)
    header_line, header = rows[0]
    names = [c.strip() for c in header]
    missing = [c for c in COLUMNS if c not in names]
    if missing:
        raise VtsError(f"motion log lacks column(s) {', '.join(missing)} (needs "
                       f"{','.join(COLUMNS)}; header on line {header_line}: {','.join(names)})",
                       path)
    dup = sorted({c for c in names if names.count(c) > 1})
    if dup:
        raise VtsError(f"motion log header repeats column {dup[0]!r}", path)
    idx = [names.index(c) for c in COLUMNS]
    values: list[list[float]] = []
    for n, row in rows[1:]:
        if len(row) < len(names):
            raise VtsError(f"line {n}: {len(row)} field(s), the header has {len(names)}", path)
        rec = []
        for col, i in zip(COLUMNS, idx, strict=True):
            cell = row[i].strip()
            try:
                v = float(cell)
            except ValueError:
                raise VtsError(f"line {n}: {col} is not a number: {cell!r}", path) from None
            if not math.isfinite(v):
                raise VtsError(f"line {n}: {col} is not finite: {cell!r}", path)
            rec.append(v)
        if values and rec[0] <= values[-1][0]:
            raise VtsError(f"line {n}: t_s {rec[0]:g} is not after the previous {values[-1][0]:g} "
                           "(times must increase)", path)
        values.append(rec)
    if len(values) < 2:
        raise VtsError(f"motion log needs at least 2 rows of data, found {len(values)}", path)
    a = np.asarray(values, dtype=np.float64)
    return MotionLog(str(path), a[:, 0], a[:, 1], a[:, 2], a[:, 3])
