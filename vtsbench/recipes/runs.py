"""Training runs on disk (`vtsbench train`): a recipe trained into a folder, the config.json that
marks the run finished, and reading a finished run's config back."""

from __future__ import annotations

import contextlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import VtsError

#: The merged config, written once training succeeded: its presence marks a finished run.
CONFIG_NAME = "config.json"


@dataclass(frozen=True)
class TrainedRun:
    """A finished training run: the recipe's name, its checkpoint and the config it used."""

    recipe: str
    checkpoint: Path
    config: dict[str, Any]


def train_run(recipe: str, dataset: str | Path, split: str, out: str | Path, *,
              config: str | Path | None = None, seed: int = 0, device: str = "auto",
              resume: bool = True, progress: bool = True) -> TrainedRun:
    """Train RECIPE (a registered name or a .py file) on SPLIT's train part into OUT, with its
    default config updated by the CONFIG file, and mark the run finished.

    A run that fails before its first checkpoint leaves no folder behind; one that has
    checkpoints keeps them, so that the next train resumes."""
    from .config import load_config
    from .registry import guarded, load_recipe

    rec = load_recipe(recipe)
    cfg = load_config(rec, config)
    out = Path(out)
    existed = out.exists()
    out.mkdir(parents=True, exist_ok=True)
    try:
        ckpt = guarded(rec.train, f"recipe {recipe}")(dataset, split, out, cfg, seed=seed,
                                                      device=device, resume=resume,
                                                      progress=progress)
    except BaseException:
        if not existed:
            with contextlib.suppress(OSError):
                out.rmdir()
        raise
    finish_run(out, cfg)
    return TrainedRun(rec.name, ckpt, cfg)


def finish_run(out: str | Path, config: dict[str, Any]) -> Path:
    """Write the run's merged config (OUT/config.json), which marks the run finished."""
    from ..atomic import write_text_atomic

    path = Path(out) / CONFIG_NAME
    write_text_atomic(path, json.dumps(config, indent=1, sort_keys=True) + "\n")
    return path


def read_run_config(out: str | Path) -> dict[str, Any]:
    """The config a finished run in OUT trained with; a VtsError if the run never finished."""
    from ..jsonio import read_json

    path = Path(out) / CONFIG_NAME
    if not path.is_file():
        raise VtsError(f"not a finished training run (no {CONFIG_NAME})", out)
    config = read_json(path, "run config")
    if not isinstance(config, dict):
        raise VtsError("run config is not a mapping of option names to values", path)
    return config
