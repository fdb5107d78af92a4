"""What the background's checks cost `calibrate`: loading the presses (frames, background, every
circle detected and checked) with and without the checks of a given background against the
presses' median (`calibration._background_warnings`: its channel order, `background.
channels_reversed`, and a contact of its own, `background.own_contact`), in alternated rounds on
the same folder, and the checks alone; then the search for presses under another light than the
background (`background.light_mates`, which every calibration runs) alone, and loading with and
without the check of their circles against one another (`calibration._detect_against_mates`).

Folders: simulated presses (`vtsbench simulate`, 480x640 at 0.03 mm/px, 30 presses) and, when
../shared/data/real is there, Taxim's 49 presses (120x160) with their background.

    .venv/bin/python benchmarks/background_checks.py [--rounds 5]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from circles_real import REAL  # the shared real recordings
from machine import machine  # benchmarks/machine.py: the shared machine line


def folders(tmp: Path) -> list[tuple[str, Path]]:
    """(name, recordings folder) of each set timed here."""
    from vtsbench.sim.simulate import simulate

    out = [("simulated, 30 presses of 480x640", tmp / "sim")]
    simulate(out[0][1], seed=2, n_static=0, n_sequences=0, n_presses=30)
    pack = REAL / "taxim_gelsight_ball" / "dataPack_small.npz"
    if pack.is_file():
        from vtsbench.recordings.taxim import taxim_recordings

        out.append(("Taxim, 49 presses of 120x160", taxim_recordings(pack, tmp / "taxim")))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args()
    import vtsbench.depth.calibration as cal
    from vtsbench.depth.sphere import ball_radius_px

    check = cal._background_warnings
    print("| presses | load with the checks, s | without, s | ratio | the checks alone, s |")
    print("|---|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        sets = folders(Path(tmp))
        for name, root in sets:
            w, wo = load_times("_background_warnings", root, {}, args.rounds)
            _, bg, setup, _ = cal.load_presses(root)
            frames = list(setup["frames"].values())
            ball = ball_radius_px(setup["ball_radius_mm"], setup["mm_per_px"])
            t0 = time.perf_counter()
            for _ in range(args.rounds):
                check(bg, "", frames, ball)
            alone = (time.perf_counter() - t0) / args.rounds
            print(f"| {name} | {w:.2f} | {wo:.2f} | {w / wo:.2f}x | {alone:.3f} |", flush=True)
        print("\n| presses | presses under another light | the search alone, s | load with the "
              "check against them, s | without, s | ratio |\n|---|---|---:|---:|---:|---:|")
        digit = digit_folder(Path(tmp) / "digit")
        for name, root in sets + ([("DIGIT, 16 presses of 320x240, estimated background",
                                    digit)] if digit else []):
            opts = {"mm_per_px": 1 / 21.09, "estimate_background": True} if root == digit \
                else {}
            light_row(name, root, opts, args.rounds)
    print(f"\nBest of {args.rounds} alternated rounds. Machine: {machine()}")


def load_times(check: str, root: Path, opts: dict, rounds: int) -> tuple[float, float]:
    """Best of `rounds` times (s) of `load_presses` with and without the calibration module's
    `check` (a function returning warnings), alternated in each round."""
    import vtsbench.depth.calibration as cal

    real = getattr(cal, check)
    times: dict[str, list[float]] = {"with": [], "without": []}
    try:
        for _ in range(rounds):
            for mode in times:
                setattr(cal, check, real if mode == "with" else (lambda *a, **k: []))
                t0 = time.perf_counter()
                cal.load_presses(root, **opts)
                times[mode].append(time.perf_counter() - t0)
    finally:
        setattr(cal, check, real)
    return min(times["with"]), min(times["without"])


def digit_folder(tmp: Path) -> Path | None:
    """The DIGIT presses as a recordings folder (two of them under another light), if here."""
    from typer.testing import CliRunner

    from vtsbench.cli import app

    src = REAL / "digit_ball_6mm"
    if not (src / "sphere.csv").is_file():
        return None
    res = CliRunner().invoke(app, ["manifest", str(src), "--pattern", "{name}.png", "--kind",
                                   "press", "--ball-radius-mm", "3", "--circles",
                                   str(src / "sphere.csv"), "--out", str(tmp)])
    return tmp if res.exit_code == 0 else None


def light_row(name: str, root: Path, opts: dict, rounds: int) -> None:
    """One row: `background.light_mates` alone, and loading with and without
    `calibration._detect_against_mates`, alternated."""
    import vtsbench.depth.calibration as cal
    from vtsbench.depth.background import light_mates

    w, wo = load_times("_detect_against_mates", root, opts, rounds)
    _, bg, setup, _ = cal.load_presses(root, **opts)
    t0 = time.perf_counter()
    for _ in range(rounds):
        groups = light_mates(setup["frames"], bg)
    alone = (time.perf_counter() - t0) / rounds
    print(f"| {name} | {', '.join(sorted(groups)) or 'none'} | {alone:.4f} | {w:.2f} | "
          f"{wo:.2f} | {w / wo:.2f}x |", flush=True)


if __name__ == "__main__":
    main()
