"""Named, versioned benchmark configurations of the synthetic sensor, and the one call that makes
one: simulate -> calibrate -> build, resumable (`vtsbench benchmark NAME OUT`).

A configuration fixes everything that decides the dataset's bytes (generator, gel, seed, counts,
frame size, scale, calibration, build seed) so that the same name and seed give the same dataset
on any machine; its `dataset_version` is written into the dataset, so leaderboard entries say
which benchmark they were scored on. `v2` is the published benchmark; `v2-demo` is the smaller
profile of the same generator that `make demo` runs.
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import VtsError

#: What a finished step leaves beside the recordings: the configuration it was made with.
CONFIG_FILE = "benchmark.json"


@dataclass(frozen=True)
class BenchmarkConfig:
    """One benchmark: the simulator's settings, the calibration and the dataset version."""

    name: str
    dataset_version: str
    description: str
    seed: int = 0
    generator: int = 2
    gel: str = "plain"
    size: tuple[int, int] = (240, 320)
    mm_per_px: float = 0.06
    static: int = 3000
    sequences: int = 3600
    presses: int = 20
    objects: int = 15
    sessions: int = 3
    frames: int = 8
    calibration_method: str = "lut"
    holdout: int = 4

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["size"] = list(self.size)
        return d


#: The benchmarks by name. v2: the unseen_objects test part at the paper's size (5 of 15 objects
#: held out: 1,200 sequences, 400 a state) and a static test session of 1,000 frames; 240x320 at
#: 0.06 mm/px is a GelSight Mini's usual frame (about 15 x 20 mm of gel).
BENCHMARKS: dict[str, BenchmarkConfig] = {
    "v2": BenchmarkConfig(
        name="v2", dataset_version="2.0.0",
        description="generator 2 (realistic slip), plain gel, 3,600 sequences and 3,000 static "
                    "frames at 240x320"),
    "v2-demo": BenchmarkConfig(
        name="v2-demo", dataset_version="2.0.0+demo", static=300, sequences=360,
        description="the demo profile of v2: the same generator and sensor, 360 sequences and "
                    "300 static frames"),
}


def get_config(name: str, seed: int | None = None) -> BenchmarkConfig:
    """The named configuration, with another seed if given (a check on a seed never used)."""
    if name not in BENCHMARKS:
        raise VtsError(f"unknown benchmark {name!r} (known: {', '.join(BENCHMARKS)})")
    cfg = BENCHMARKS[name]
    return cfg if seed is None else dataclasses.replace(cfg, seed=seed)


def _done_steps(folder: Path, cfg: BenchmarkConfig) -> list[str]:
    """The steps that finished in folder with this very configuration (none for another)."""
    p = folder / CONFIG_FILE
    if not p.is_file():
        return []
    try:
        doc = json.loads(p.read_text())
    except (OSError, ValueError):
        return []
    return list(doc.get("done", [])) if doc.get("config") == cfg.to_dict() else []


def _done(folder: Path, cfg: BenchmarkConfig, step: str) -> bool:
    """Whether `step` finished in folder with this very configuration."""
    return step in _done_steps(folder, cfg)


def _mark(folder: Path, cfg: BenchmarkConfig, step: str) -> None:
    """Record that `step` finished in folder with this configuration."""
    from ..atomic import write_text_atomic

    doc = {"config": cfg.to_dict(), "done": sorted({*_done_steps(folder, cfg), step})}
    write_text_atomic(folder / CONFIG_FILE, json.dumps(doc, indent=1) + "\n")


def make_benchmark(name: str, out: str | Path, *, seed: int | None = None, workers: int = 1,
                   overwrite: bool = False, progress: bool = False,
                   log: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Simulate, calibrate and build benchmark `name` into OUT/recordings and OUT/dataset.

    Resumable: a rerun keeps the recordings and calibration made with the same configuration
    and the build resumes its finished shards. Returns what was made and the seconds of each
    step."""
    from ..dataset.build import BuildOptions, build
    from ..dataset.format.layout import INFO_PATH
    from ..depth.calibration import calibrate, save_calibration
    from ..depth.report import write_report
    from .simulate import simulate

    cfg = get_config(name, seed)
    say = log or (lambda _m: None)
    out = Path(out)
    rec, ds = out / "recordings", out / "dataset"
    if out.exists() and not out.is_dir():
        raise VtsError("not a folder", out)
    if (ds / INFO_PATH).exists() and not overwrite:
        raise VtsError("the benchmark's dataset exists (use --overwrite to make it again)", ds)
    seconds: dict[str, float] = {}
    t = time.perf_counter()
    if overwrite or not _done(rec, cfg, "simulate"):
        say(f"simulating {cfg.name} (seed {cfg.seed}): {cfg.description}")
        simulate(rec, seed=cfg.seed, n_static=cfg.static, n_sequences=cfg.sequences,
                 n_presses=cfg.presses, n_objects=cfg.objects, size=cfg.size,
                 frames=cfg.frames, n_sessions=cfg.sessions, mm_per_px=cfg.mm_per_px,
                 workers=workers, overwrite=True, progress=progress,
                 generator=cfg.generator, gel=cfg.gel)
        _mark(rec, cfg, "simulate")
    seconds["simulate"] = time.perf_counter() - t
    t = time.perf_counter()
    cal = rec / "calibration.safetensors"
    if overwrite or not cal.is_file() or not _done(rec, cfg, "calibrate"):
        run = calibrate(rec, method=cfg.calibration_method, holdout=cfg.holdout, seed=0,
                        log=say)
        save_calibration(run.calibration, cal)
        write_report(run, cal.with_name(cal.name + ".report"))
        _mark(rec, cfg, "calibrate")
    seconds["calibrate"] = time.perf_counter() - t
    t = time.perf_counter()
    res = build(rec, ds, BuildOptions(calibration=cal, workers=workers, overwrite=overwrite,
                                      version=cfg.dataset_version, seed=0, progress=progress),
                log=say)
    seconds["build"] = time.perf_counter() - t
    return {"config": cfg.to_dict(), "recordings": str(rec), "dataset": str(ds),
            "seconds": seconds, "build": res}
