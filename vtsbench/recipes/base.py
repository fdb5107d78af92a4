"""The `Recipe` contract: what `vtsbench train` and `vtsbench predict` call on a recipe, and the
check that an object a recipe file or entry point gives has those members."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vtsbench.errors import VtsError


class Recipe:
    """Base class of a recipe (subclass it, or write any object with the same members).

    - `name`: short identifier, written into the submission's metadata.
    - `tasks`: the submission tasks it predicts, e.g. ("state", "direction") or ("object",).
    - `default_config()`: a JSON-able dict; a `--config` file overrides some of its keys.
    - `train(dataset_path, split, out_dir, config, *, seed, device, resume, progress)`: fit on
      the split's `train` part (and `val` if it wants), write a checkpoint under out_dir and
      return its path. With `resume`, continue from the last checkpoint found in out_dir.
    - `predict(checkpoint, dataset_path, split, part, *, device)`: a list of submission rows
      (dicts with `sample_id`, `task`, `pred` and optional `score_k`) for every sample of part.
    - optional `nullable`: config keys that take null besides their default's type (e.g.
      `threads`: null for torch's default).
    - optional, read by `vtsbench predict` into the submission's metadata: `latency_s` (seconds
      per sample of the last predict) and `input_scale_xy` (model-input pixels per sensor pixel,
      x and y, of the last predict; the per-distance scores give pixels at the model's input).
    - optional `window_predictor(checkpoint, device)`: a `WindowPredictor`, what the live
      monitor (`vtsbench.recipes.monitor`, `vtsbench stream`) calls on each window of RGB
      frames; it reads the checkpoint once, so that its calls do no file I/O.
    """

    name: str = "recipe"
    tasks: tuple[str, ...] = ()
    nullable: frozenset[str] = frozenset()

    def __init__(self) -> None:
        self.latency_s: list[float] = []
        self.input_scale_xy: tuple[float, float] | None = None

    def default_config(self) -> dict[str, Any]:
        return {}

    def train(self, dataset_path: str | Path, split: str, out_dir: str | Path,
              config: dict[str, Any], *, seed: int = 0, device: str = "auto",
              resume: bool = True, progress: bool = True) -> Path:
        raise NotImplementedError

    def predict(self, checkpoint: str | Path, dataset_path: str | Path, split: str,
                part: str = "test", *, device: str = "auto") -> list[dict[str, Any]]:
        raise NotImplementedError


@dataclass(frozen=True)
class WindowPredictor:
    """A recipe's prediction on one window of a live RGB stream, and what it needs to know.

    `predict(window)`: window (frames, H, W, 3) uint8 RGB, oldest frame first -> a dict of
    `state_probs` (len(STATES) floats), `direction` (bin 0..7) and optional `direction_probs`
    (8 floats) for a slip recipe, `object_probs` for an object recipe: the probabilities of
    `classes[task]`. `frames`: the window's length; `size`: the (H, W) the checkpoint was
    trained at (None: any size, fixed by the first frame); `arrays`: what the checkpoint was
    fitted on (a live stream gives rgb alone); `note`: what the recipe does without the
    others."""

    predict: Callable[[Any], dict[str, Any]]
    frames: int
    size: tuple[int, int] | None
    classes: dict[str, tuple[str, ...]]
    arrays: tuple[str, ...] = ("rgb",)
    note: str = ""

    def __call__(self, window: Any) -> dict[str, Any]:
        return self.predict(window)


#: The members every recipe has.
REQUIRED = ("name", "tasks", "default_config", "train", "predict")


def as_recipe(obj: Any, where: str) -> Any:
    """OBJ as a recipe (a class is instantiated); one missing a member of the contract is a
    one-line VtsError naming WHERE it came from."""
    if isinstance(obj, type):
        obj = obj()
    missing = [m for m in REQUIRED if not hasattr(obj, m)]
    if missing:
        raise VtsError(f"not a recipe: missing {', '.join(missing)}", where)
    return obj
