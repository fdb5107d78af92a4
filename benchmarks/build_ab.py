"""Build throughput of this vtsbench against another source tree of it, in one run, alternating.

Run: .venv/bin/python benchmarks/build_ab.py --old /path/to/other/checkout [--recordings DIR]
     [--rounds 4] [--workers 1]

Each round builds the same recordings twice in fresh processes (`python -m vtsbench build`),
once with PYTHONPATH at --old and once at this tree, swapping which goes first every round, and
prints frames/s per run, the median of each and their ratio (this / old): on a shared machine
only the ratio of alternated runs means anything. Without --recordings it simulates 60 static
frames and 60 sequences of 8 frames at 480x640 and calibrates them (lut) in a temporary folder.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]


def vtsbench(tree: Path, *args: str) -> float:
    """Seconds of one `python -m vtsbench ARGS` with PYTHONPATH at tree (raises on failure)."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "vtsbench", *args], check=True, env=env, cwd=tree,
                   stdout=subprocess.DEVNULL)
    return time.perf_counter() - t0


def frames_of(ds: Path) -> int:
    """Frames of a built dataset (static samples + slip samples x T), from its build report."""
    import json

    report = json.loads((ds / "meta" / "build_report.json").read_text())
    return sum(k["frames"] for k in report["built"].values())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old", type=Path, required=True, help="source tree of the other vtsbench")
    ap.add_argument("--recordings", type=Path, default=None)
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--workers", type=int, default=1)
    a = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="vtsbench-ab-"))
    try:
        rec = a.recordings
        if rec is None:
            rec = work / "rec"
            vtsbench(HERE, "simulate", str(rec), "--static", "60", "--sequences", "60",
                     "--presses", "12", "--quiet")
            vtsbench(HERE, "calibrate", str(rec), "--out", str(rec / "calibration.safetensors"),
                     "--method", "lut")
        trees = {"old": a.old.resolve(), "this": HERE}
        runs: dict[str, list[float]] = {"old": [], "this": []}
        n = 0
        for r in range(a.rounds):
            for name in (("old", "this") if r % 2 == 0 else ("this", "old")):
                out = work / f"ds-{name}"
                shutil.rmtree(out, ignore_errors=True)
                s = vtsbench(trees[name], "build", str(rec), str(out), "--workers",
                             str(a.workers), "--quiet")
                n = frames_of(out)
                runs[name].append(n / s)
                print(f"round {r + 1} {name}: {n} frames in {s:.1f} s, {n / s:.1f} frames/s",
                      flush=True)
        med = {k: statistics.median(v) for k, v in runs.items()}
        from build import machine  # benchmarks/build.py: cores and CPU model

        print(f"\n{machine()}; {n} frames, "
              f"{a.workers} worker(s), {a.rounds} alternated rounds")
        print("| code | frames/s (median) | runs |\n|---|---:|---|")
        for k in ("old", "this"):
            print(f"| {k} | {med[k]:.1f} | {', '.join(f'{v:.1f}' for v in runs[k])} |")
        print(f"\nratio this / old: {med['this'] / med['old']:.3f}")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
