"""Ablation of generator 2's effects: the same slip sequences scored by the phase-correlation
reference and the flow recipe's direction, with each effect switched off in turn.

Run: .venv/bin/python benchmarks/sim_ablation.py [--sequences 120] [--size 240x320]
     [--mm-per-px 0.06] [--seed 0] [--gel plain] [--workers 2]

Every row renders the same planned slips (entry generators seeded by (seed, 'sequence', k)
as `vtsbench simulate` does; generator 1 draws its own slip distances from its range): generator
1, generator 2 with its defaults, and generator 2 with one mechanics or appearance effect off.
The score is the direction accuracy over the sequences that the labelling rule calls a slip,
with a 95 % Wilson interval:

- phase-correlation reference: `cv2.phaseCorrelate` of the whole first and last grey frames
  (no window), the angle binned to the 8 classes, as `benchmarks/results.py` scores it; the
  share of shifts under 0.5 px (the registration sees almost no motion) is shown beside it;
- flow recipe: the direction rule of `vtsbench/recipes/builtin/flow.py` (`global_shift`: the
  first frame against the last inside the window where the gel moves; no training, the
  recipe's tree decides the state only).

Prints a markdown table and the machine line.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from machine import machine  # benchmarks/machine.py: the shared machine line
from slip_effects import wilson  # benchmarks/slip_effects.py: the 95 % Wilson interval

from vtsbench.sim.appearance import GELS, sensor_appearance
from vtsbench.sim.mechanics import Mechanics

#: Rows: (name, generator, mechanics changes, appearance changes, gel shear on).
Variant = tuple[str, int, dict, dict | None, bool]


def variants(gel: str) -> list[Variant]:
    """The rows of the table for a sensor wearing `gel`."""
    other = "markers" if gel == "plain" else "plain"
    pattern_off = {"border_darkness": (0.0, 0.0), "dust_per_cm2": 0.0, "scratches": 0,
                   "marker_share": 0.0, "grain": 0.0}
    return [
        ("generator 1", 1, {}, {}, True),
        ("generator 2, defaults", 2, {}, {}, True),
        ("- partial slip and gel shear (pattern does not ride the gel)", 2, {}, {}, False),
        ("- rotation", 2, {"rotation_deg": (0.0, 0.0)}, {}, True),
        ("- uneven speed (steady profile only)", 2, {"profile_mix": (1.0, 0.0, 0.0, 0.0)}, {},
         True),
        ("- contact made or lost", 2, {"contact_change_share": 0.0}, {}, True),
        ("- fixed pattern (markers, border, dust, scratches, grain)", 2, {}, pattern_off,
         True),
        (f"{other} gel instead of {gel}", 2, {}, {"marker_share":
                                                   1.0 if other == "markers" else 0.0}, True),
        ("- weak imprint (imprint gain 1)", 2, {}, {"imprint_gain": (1.0, 1.0)}, True),
        ("- compression", 2, {}, {"jpeg_quality": None}, True),
        ("- key frames (blocks re-sent only when changed)", 2, {}, {"keyframe_interval": None},
         True),
        ("- white-balance jump and drift", 2, {}, {"wb_jump_share": 0.0, "drift": 0.0}, True),
        ("- noise (noise scale 0)", 2, {}, {"noise_scale": 0.0}, True),
        ("- the whole appearance (mechanics only)", 2, {}, None, True),
    ]


def score_one(task: tuple) -> tuple[int, bool, bool, bool, bool] | None:
    """(row, phase right, phase shift under 0.5 px, flow phase rule right, flow contact rule
    right (on the rendered contact masks)) of one sequence; None when not a slip."""
    import cv2

    from vtsbench.labels import angle_to_class, label_contact_window
    from vtsbench.recipes.builtin.flow import contact_motion, global_shift
    from vtsbench.sim.objects import OBJECTS
    from vtsbench.sim.optics import Capture
    from vtsbench.sim.plan import EntryPlan, entry_rng, sequence_plan_scene
    from vtsbench.sim.scene import render

    cv2.setNumThreads(1)
    row, (_name, gen, mech, app, shear), k, seed, size, mpp, frames, gel = task
    plan = EntryPlan("sequence", k, 0, OBJECTS[(k - 1) % len(OBJECTS)].name, "slip")
    rng = entry_rng(seed, "sequence", k)
    appearance = None
    if gen >= 2 and app is not None:
        appearance = dataclasses.replace(sensor_appearance(gel), **app)
    scene, motion = sequence_plan_scene(plan, rng, size, mpp, frames, gen, appearance,
                                        dataclasses.replace(Mechanics(), **mech))
    if gen >= 2 and app is None:
        scene = dataclasses.replace(scene, appearance=None)
    if not shear:
        scene = dataclasses.replace(scene, mechanics=None)
    r = render(scene, Capture(read_noise=1.5, gel=seed), rng)
    if gen >= 2:
        lab = label_contact_window(motion.positions_mm(frames), scene.depths_mm,
                                   r.contact.any(axis=(1, 2)).tolist())
    else:
        lab = motion.label()
    if lab.state != "slip" or lab.direction is None:
        return None
    g = [cv2.cvtColor(f, cv2.COLOR_RGB2GRAY).astype(np.float32) for f in (r.frames[0],
                                                                           r.frames[-1])]
    (sx, sy), _ = cv2.phaseCorrelate(g[0], g[1])  # as benchmarks/results.py's reference
    miss = math.hypot(sx, sy) < 0.5
    pc_ok = angle_to_class(math.degrees(math.atan2(-sy, sx)) % 360) == lab.direction
    dx, dy, _ = global_shift(r.frames)
    flow_ok = bool(dx or dy) and \
        angle_to_class(math.degrees(math.atan2(-dy, dx)) % 360) == lab.direction
    cm = contact_motion(r.frames, r.contact)
    contact_ok = cm is not None and bool(cm[0] or cm[1]) and \
        angle_to_class(math.degrees(math.atan2(-cm[1], cm[0])) % 360) == lab.direction
    return row, pc_ok, miss, flow_ok, contact_ok


def _init() -> None:
    import cv2

    cv2.setNumThreads(1)


def main() -> None:
    """Render, score and print the ablation table."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sequences", type=int, default=120, help="slip sequences per row")
    ap.add_argument("--size", default="240x320", help="frame size HxW")
    ap.add_argument("--mm-per-px", type=float, default=0.06,
                    help="scale (0.06 at 240x320 keeps the default sensor's field of view)")
    ap.add_argument("--frames", type=int, default=8)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--gel", choices=GELS, default="plain")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--rows", default="", help="comma-separated row numbers (default: all)")
    args = ap.parse_args()
    h, w = (int(v) for v in args.size.lower().split("x"))
    rows = variants(args.gel)
    chosen = [int(v) for v in args.rows.split(",") if v] or list(range(len(rows)))
    tasks = [(i, rows[i], k, args.seed, (h, w), args.mm_per_px, args.frames, args.gel)
             for i in chosen for k in range(1, args.sequences + 1)]
    t0 = time.perf_counter()
    if args.workers > 1:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        ctx = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(args.workers, mp_context=ctx, initializer=_init) as pool:
            results = list(pool.map(score_one, tasks, chunksize=8))
    else:
        results = [score_one(t) for t in tasks]
    secs = time.perf_counter() - t0
    print(f"Direction accuracy on slipping sequences: {args.sequences} planned slips per row "
          f"(seed {args.seed}), {h}x{w} at {args.mm_per_px:g} mm/px, {args.frames} frames, "
          f"{args.gel} gel; 95 % Wilson intervals\n")
    print("| row | slips | phase-correlation reference | shift under 0.5 px "
          "| flow recipe's phase rule (direction) | flow recipe's contact rule (direction) |")
    print("|---|---:|---:|---:|---:|---:|")
    for i in chosen:
        got = [r for r in results if r is not None and r[0] == i]
        n = len(got)
        pc = sum(r[1] for r in got)
        miss = sum(r[2] for r in got)
        fl = sum(r[3] for r in got)
        co = sum(r[4] for r in got)
        lo, hi = wilson(pc, n) or (0.0, 1.0)
        flo, fhi = wilson(fl, n) or (0.0, 1.0)
        clo, chi = wilson(co, n) or (0.0, 1.0)
        print(f"| {rows[i][0]} | {n} | {100 * pc / max(n, 1):.1f} % [{100 * lo:.0f}-"
              f"{100 * hi:.0f}] | {100 * miss / max(n, 1):.0f} % | {100 * fl / max(n, 1):.1f} % "
              f"[{100 * flo:.0f}-{100 * fhi:.0f}] | {100 * co / max(n, 1):.1f} % "
              f"[{100 * clo:.0f}-{100 * chi:.0f}] |")
    print(f"\n{len(tasks)} sequences rendered and scored in {secs:.0f} s with {args.workers} "
          f"workers.\nMachine: {machine()}")


if __name__ == "__main__":
    main()
