"""Simulator throughput on one core: frames/s per scene kind, minimal effects vs all forced.

Run: .venv/bin/python benchmarks/simulator.py [--scenes 15] [--size 480x640] [--mm-per-px 0.03]

For each scene kind (static frame, held sequence, press sequence, slip sequence, calibration
press) the same scenes are rendered with the effects the simulator gives them and with every
effect forced on and nothing cropped (Effects.everything()); then rendered and written (PNG
frames + truth .npz) as `vtsbench simulate` does; then the generator-2 scenes (contact
mechanics, uneven speed, contact made or lost, the gel's pattern and camera). Prints a markdown
table and the machine.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from machine import machine  # benchmarks/machine.py: the shared machine line

from vtsbench.recordings.media import write_png
from vtsbench.recordings.truth import Truth, write_truth
from vtsbench.sim.objects import OBJECTS
from vtsbench.sim.optics import Capture, sensor
from vtsbench.sim.plan import (
    EntryPlan,
    press_scene,
    sequence_plan_scene,
    static_scene,
)
from vtsbench.sim.scene import Effects, Scene, render

KINDS = ("static frame", "held sequence", "press sequence", "slip sequence", "calibration press")
#: (kind, generator) rows of the table: every kind of generator 1, then generator 2's.
ROWS = tuple((k, 1) for k in KINDS) + tuple((k, 2) for k in KINDS)


def make_scenes(kind: str, n: int, size: tuple[int, int], mm_per_px: float,
                frames: int, generator: int = 1) -> list[Scene]:
    """n scenes of a kind, cycling over the 15 object classes, as the simulator draws them."""
    scenes = []
    state = {"held sequence": "static", "press sequence": "press", "slip sequence": "slip"}
    for i in range(n):
        rng = np.random.default_rng([12345, KINDS.index(kind), i])
        obj = OBJECTS[i % len(OBJECTS)].name
        if kind == "static frame":
            scenes.append(static_scene(EntryPlan("static", i + 1, 0, obj), rng, size, mm_per_px,
                                       generator))
        elif kind == "calibration press":
            scenes.append(press_scene(rng, size, mm_per_px, generator))
        else:
            plan = EntryPlan("sequence", i + 1, 0, obj, state[kind])
            scenes.append(sequence_plan_scene(plan, rng, size, mm_per_px, frames,
                                              generator)[0])
    return scenes


def timed(scenes: list[Scene], fn: Callable[[Scene, np.random.Generator], None],
          repeats: int) -> float:
    """Best-of-repeats frames per second of fn over the scenes."""
    n_frames = sum(s.n_frames for s in scenes)
    best = float("inf")
    for _ in range(repeats):
        rng = np.random.default_rng(0)
        t0 = time.perf_counter()
        for s in scenes:
            fn(s, rng)
        best = min(best, time.perf_counter() - t0)
    return n_frames / best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", type=int, default=15, help="scenes per kind (default 15)")
    ap.add_argument("--size", default="480x640", help="frame size HxW (default 480x640)")
    ap.add_argument("--mm-per-px", type=float, default=0.03)
    ap.add_argument("--frames", type=int, default=8, help="frames per sequence")
    ap.add_argument("--repeats", type=int, default=2, help="best of this many runs")
    args = ap.parse_args()
    h, w = (int(v) for v in args.size.lower().split("x"))
    size = (h, w)

    import cv2

    cv2.setNumThreads(1)
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})  # one core
    capture = Capture()
    sensor(h, w, args.mm_per_px)  # per-process cache, built once like in a worker
    sensor(h, w, args.mm_per_px, True, True)

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)

        def write(scene: Scene, rng: np.random.Generator) -> None:
            r = render(scene, capture, rng)
            for t, frame in enumerate(r.frames):
                write_png(out / f"{t:03d}.png", frame)
            write_truth(out / "truth.npz", Truth(r.depth_mm, r.grad, r.contact, r.motion_px))

        for kind, gen in ROWS:
            scenes = make_scenes(kind, args.scenes, size, args.mm_per_px, args.frames, gen)
            forced = [s.with_effects(Effects.everything()) for s in scenes]
            render(scenes[0], capture, np.random.default_rng(0))  # warm-up (lazy imports)
            minimal = timed(scenes, lambda s, rng: render(s, capture, rng), args.repeats)
            full = timed(forced, lambda s, rng: render(s, capture, rng), args.repeats)
            written = timed(scenes, write, args.repeats)
            rows.append((f"{kind}, generator {gen}", sum(s.n_frames for s in scenes), minimal,
                         full, written))
    print(f"Simulator throughput at {h}x{w}, {args.mm_per_px} mm/px, one core "
          f"(best of {args.repeats}; {args.scenes} scenes per kind, objects cycling over the 15 "
          "classes)\n")
    print("| scene kind | frames | render, minimal effects (frames/s) | render, all effects "
          "forced (frames/s) | speed-up | render + write PNG and truth (frames/s) |")
    print("|---|---:|---:|---:|---:|---:|")
    for kind, n, minimal, full, written in rows:
        print(f"| {kind} | {n} | {minimal:.1f} | {full:.1f} | {minimal / full:.1f}x | "
              f"{written:.1f} |")
    for gen in (1, 2):
        part = [r for r in rows if r[0].endswith(f"generator {gen}")]
        tot = sum(r[1] for r in part)

        def overall(i: int, part=part, tot=tot) -> float:
            return tot / sum(r[1] / r[i] for r in part)

        print(f"| all kinds, generator {gen} | {tot} | {overall(2):.1f} | {overall(3):.1f} | "
              f"{overall(2) / overall(3):.1f}x | {overall(4):.1f} |")
    print(f"\nMachine: {machine()}")


if __name__ == "__main__":
    main()
