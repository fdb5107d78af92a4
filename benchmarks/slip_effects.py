"""Direction accuracy of the results page's slip runs broken down by what generator 2 does to a
sequence (speed profile, contact made or lost, rotation, object group), with 95 % intervals;
used by benchmarks/results.py."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

#: Rotation of the object over the window (|turn_deg|), bins in degrees.
TURN_BINS = ((0.0, 0.5), (0.5, 1.0), (1.0, math.inf))


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float] | None:
    """95 % Wilson interval (fractions) of k successes in n; None for n = 0."""
    if n <= 0:
        return None
    p = k / n
    c = (p + z * z / (2 * n)) / (1 + z * z / n)
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, c - h), min(1.0, c + h)


def slip_truth(dataset: Path, split: str) -> dict[str, dict[str, Any]]:
    """The slipping test sequences of a split: sample id -> direction and effect labels."""
    import vtsbench

    idx = vtsbench.load(dataset).split(split, "test").index.to_pylist()
    out = {}
    for r in idx:
        if r.get("state") != "slip" or r.get("direction") is None:
            continue
        turn = r.get("turn_deg")
        try:
            turn = abs(float(turn)) if turn not in (None, "") else None
        except ValueError:
            turn = None
        out[r["sample_id"]] = {
            "direction": int(r["direction"]), "profile": r.get("profile") or "-",
            "contact": r.get("contact_change") or "kept", "turn": turn,
            "group": r.get("group") or "-"}
    return out


def submission_hits(csv: Path, truth: dict[str, dict[str, Any]]) -> dict[str, bool]:
    """Per slipping sequence: whether the submission's direction is right (state given)."""
    import pyarrow.csv as pacsv

    t = pacsv.read_csv(csv, convert_options=pacsv.ConvertOptions(
        column_types={"sample_id": "string", "task": "string", "pred": "string"})).to_pylist()
    pred = {r["sample_id"]: r["pred"] for r in t if r["task"] == "direction"}
    return {sid: str(pred.get(sid)) == str(v["direction"]) for sid, v in truth.items()}


def _turn_bin(turn: float | None) -> str:
    if turn is None:
        return "-"
    for lo, hi in TURN_BINS:
        if lo <= turn < hi:
            return f"[{lo:g}, {hi:g})" if math.isfinite(hi) else f">= {lo:g}"
    return "-"


def effect_keys(v: dict[str, Any]) -> list[tuple[str, str]]:
    """(effect, value) pairs of one sequence, in table order."""
    return [("speed profile", v["profile"]), ("contact in the window", v["contact"]),
            ("rotation over the window, deg", _turn_bin(v["turn"])),
            ("object group", v["group"])]


def _cell(hits: list[bool]) -> str:
    if not hits:
        return "-"
    k, n = sum(hits), len(hits)
    lo, hi = wilson(k, n) or (0.0, 0.0)
    return f"{100 * k / n:.1f} [{100 * lo:.0f}-{100 * hi:.0f}]"


def effect_table(truth: dict[str, dict[str, Any]], columns: list[tuple[str, dict[str, bool]]]
                 ) -> list[str]:
    """Markdown rows: effect | value | n | each column's accuracy % [95 % interval]."""
    groups: dict[tuple[str, str], list[str]] = {}
    for sid, v in truth.items():
        for key in effect_keys(v):
            groups.setdefault(key, []).append(sid)
    head = ["effect", "value", "n", *(name for name, _ in columns)]
    out = ["| " + " | ".join(head) + " |", "|---|---|---:" + "|---:" * len(columns) + "|"]
    order = [e for e, _ in effect_keys(next(iter(truth.values())))] if truth else []
    for effect in order:
        for (e, value), sids in sorted(groups.items(), key=lambda kv: kv[0][1]):
            if e != effect:
                continue
            cells = [_cell([hits[s] for s in sids if s in hits]) for _, hits in columns]
            out.append(f"| {effect} | {value} | {len(sids)} | " + " | ".join(cells) + " |")
    return out
