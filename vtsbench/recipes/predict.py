"""A recipe's predictions as a submission (`vtsbench predict`), with the metadata eval and the
leaderboards read beside the scores: split, part, checkpoint, speed, latency, environment and
the model's input scale."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import VtsError


@dataclass(frozen=True)
class Prediction:
    """What `predict_submission` wrote: rows and samples, the CSV and its metadata file."""

    rows: int
    samples: int
    submission: Path
    meta: Path


def submission_meta(recipe: Any, *, split: str, part: str, checkpoint: str | Path,
                    seconds: float, samples: int, device: str) -> dict[str, Any]:
    """The metadata of a prediction run beyond the method, dataset and seeds: what was
    predicted from what, the time per sample, the recipe's median latency and input scale when
    it reports them, and the library versions and device."""
    from ..environment import environment

    meta: dict[str, Any] = {"split": split, "part": part, "checkpoint": str(checkpoint),
                            "predict_seconds_per_sample": round(seconds / max(samples, 1), 6)}
    lat = getattr(recipe, "latency_s", None)
    if lat:
        meta["latency_ms_per_sample_median"] = round(1000 * sorted(lat)[len(lat) // 2], 3)
    meta["environment"] = environment(device)
    scale = getattr(recipe, "input_scale_xy", None)  # model-input px per sensor px (x, y)
    if scale:
        meta["input_scale_xy"] = [round(float(v), 6) for v in scale]
    return meta


def predict_submission(recipe: str, checkpoint: str | Path, dataset: str | Path, split: str,
                       out: str | Path, *, part: str = "test", device: str = "auto",
                       method: str | None = None, seed: int = 0) -> Prediction:
    """Predict a split part with RECIPE (a registered name or a .py file) from CHECKPOINT and
    write the submission OUT and OUT.meta.json; METHOD defaults to the recipe's name, SEED is
    the training seed recorded in the metadata."""
    from .checkpoints import check_checkpoint
    from .registry import guarded, load_recipe
    from .submission import write_submission

    rec = load_recipe(recipe)
    checkpoint = Path(checkpoint)
    if not checkpoint.exists():
        raise VtsError("checkpoint not found", checkpoint)
    check_checkpoint(checkpoint)
    t0 = time.perf_counter()
    rows = guarded(rec.predict, f"recipe {recipe}")(checkpoint, dataset, split, part,
                                                    device=device)
    wall = time.perf_counter() - t0
    n = len({r["sample_id"] for r in rows})
    extra = submission_meta(rec, split=split, part=part, checkpoint=checkpoint, seconds=wall,
                            samples=n, device=device)
    sub, meta = write_submission(rows, out, method=method or rec.name, dataset_path=dataset,
                                 recipe=str(recipe), seeds=[seed], extra=extra)
    return Prediction(len(rows), n, sub, meta)
