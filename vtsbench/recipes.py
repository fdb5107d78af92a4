"""Recipes: a baseline that trains on a dataset split and writes a submission `vtsbench eval`
accepts.

A recipe is an object with `name`, `tasks`, `default_config()`, `train(...)` and
`predict(...)` (the `Recipe` base class below documents the contract). It is found by
`load_recipe(name_or_path)`: a path to a Python file that defines `RECIPE`, or a name registered
under the entry-point group `vtsbench.recipes` (the built-in ones live in the top-level `recipes`
package). A recipe uses vtsbench's public API only: `vtsbench.load`, views, `to_torch`,
`vtsbench.training` and `vtsbench.labels`.
"""

from __future__ import annotations

import csv
import importlib
import importlib.util
import json
import math
import os
import sys
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

from .errors import VtsError

ENTRY_POINT_GROUP = "vtsbench.recipes"
#: The columns of a submission row, in the order they are written.
ROW_COLUMNS = ("sample_id", "task", "pred")


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


_REQUIRED = ("name", "tasks", "default_config", "train", "predict")


def _check(obj: Any, where: str) -> Any:
    if isinstance(obj, type):
        obj = obj()
    missing = [m for m in _REQUIRED if not hasattr(obj, m)]
    if missing:
        raise VtsError(f"not a recipe: missing {', '.join(missing)}", where)
    return obj


def _from_file(path: Path) -> Any:
    if not path.is_file():
        raise VtsError("recipe file not found", path)
    mod_name = f"vtsbench_recipe_{path.stem}_{abs(hash(str(path.resolve()))) & 0xFFFFFFFF:x}"
    from importlib.machinery import SourceFileLoader

    # the loader named: a recipe file without the .py suffix (./flow) is Python source too
    spec = importlib.util.spec_from_file_location(mod_name, path,
                                                  loader=SourceFileLoader(mod_name, str(path)))
    if spec is None or spec.loader is None:
        raise VtsError("cannot import the recipe file", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[mod_name] = module
    try:
        spec.loader.exec_module(module)
    except ModuleNotFoundError as e:
        sys.modules.pop(mod_name, None)
        raise VtsError(_needs(e), path) from None
    except Exception:
        sys.modules.pop(mod_name, None)
        raise
    if not hasattr(module, "RECIPE"):
        raise VtsError("the recipe file defines no RECIPE", path)
    return _check(module.RECIPE, str(path))


def registered() -> dict[str, Any]:
    """The entry points of the group `vtsbench.recipes`, by name."""
    from importlib.metadata import entry_points

    return {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP)}


def _builtin_file(name: str) -> Path | None:
    """vtsbench/recipes_builtin/NAME.py (when the installed metadata predates it)."""
    path = Path(__file__).resolve().parent / "recipes_builtin" / f"{name}.py"
    return path if path.is_file() else None


def _needs(e: ModuleNotFoundError) -> str:
    """The one-line reason of a recipe that imports a package that is not installed."""
    extra = " (pip install 'vtsbench[torch]')" if (e.name or "").split(".")[0] in (
        "torch", "torchvision", "transformers") else ""
    return f"the recipe needs the Python package {e.name!r}, which is not installed{extra}"


def guarded(fn: Callable[..., Any], where: str) -> Callable[..., Any]:
    """FN, with a package it imports only when called (a recipe's torch, transformers) that is
    not installed made one line naming WHERE and the install command."""
    def call(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except ModuleNotFoundError as e:
            raise VtsError(_needs(e), where) from None

    return call


def load_recipe(name_or_path: str | Path) -> Any:
    """A recipe from a .py file defining RECIPE, or by its registered name.

    A registered or built-in name always means that recipe, even when a file of that name is in
    the working folder; a file is given by a name ending in .py or a path with a folder
    (./flow); any other existing file is read as a recipe file too."""
    text = str(name_or_path)
    if text.endswith(".py") or "/" in text or (os.sep in text) or (
            os.altsep is not None and os.altsep in text):
        return _from_file(Path(text))
    eps = registered()
    if text in eps:
        try:
            return _check(eps[text].load(), f"entry point {text}")
        except ModuleNotFoundError as e:
            if not eps[text].module.startswith(e.name or "\0"):  # else stale metadata: below
                raise VtsError(_needs(e), f"recipe {text}") from None
    module = None
    if text.isidentifier():  # a module name: not "", ".x" or "a-b"
        try:
            module = importlib.import_module(f"vtsbench.recipes_builtin.{text}")
        except ModuleNotFoundError as e:
            if e.name and not e.name.startswith("vtsbench.recipes_builtin"):
                raise VtsError(_needs(e), f"recipe {text}") from None
    if module is not None and hasattr(module, "RECIPE"):
        return _check(module.RECIPE, f"vtsbench.recipes_builtin.{text}")
    path = _builtin_file(text) if text.isidentifier() else None
    if path is not None:
        return _from_file(path)
    if text and Path(text).is_file():
        return _from_file(Path(text))
    known = ", ".join(sorted(eps)) or "none"
    raise VtsError(f"unknown recipe {text!r} (registered: {known}; or give a path to a .py file)")


def check_checkpoint(path: str | Path) -> Path:
    """A checkpoint a recipe can open: a regular file; a .safetensors one whose header and JSON
    metadata values parse (each through the same limits as every user JSON), a .json one that
    parses; else a one-line VtsError. Other formats are the recipe's to read."""
    from .jsonio import loads, read_bytes, read_json, regular_file

    path = Path(path)
    if path.suffix == ".json":
        read_json(path, "checkpoint")
    if path.suffix != ".safetensors":
        return regular_file(path, "checkpoint")
    data = read_bytes(path, "checkpoint", 1 << 40)
    n = int.from_bytes(data[:8], "little") if len(data) >= 8 else 0
    if not 0 < n <= len(data) - 8:
        raise VtsError("not a safetensors checkpoint (no header)", path)
    head = loads(data[8:8 + n], path, "checkpoint header")
    if not isinstance(head, dict):
        raise VtsError("not a safetensors checkpoint (header is not a mapping)", path)
    meta = head.get("__metadata__") or {}
    if not isinstance(meta, dict):
        raise VtsError("not a safetensors checkpoint (metadata is not a mapping)", path)
    for key, value in meta.items():
        if isinstance(value, str) and value[:1] in "{[":
            loads(value, path, f"checkpoint metadata {key!r}")
    try:
        from safetensors.numpy import load

        load(data)
    except Exception as e:  # safetensors' own error type for damaged data
        raise VtsError(f"corrupt checkpoint ({str(e).splitlines()[0][:100]})", path) from None
    return path


def checkpoint_meta(path: str | Path, recipe: str, json_keys: Sequence[str] = ()
                    ) -> dict[str, Any]:
    """The metadata of a safetensors checkpoint that RECIPE wrote (only its header is read),
    with JSON_KEYS parsed; any other file (a CSV, another recipe's checkpoint, a damaged
    header) is a one-line VtsError naming it, whatever its suffix."""
    from .jsonio import loads, regular_file

    path = regular_file(path, "checkpoint", 1 << 40)
    not_one = VtsError(f"not a {recipe} recipe checkpoint (a safetensors file written by "
                       f"`vtsbench train {recipe}`)", path)
    try:
        with open(path, "rb") as fh:
            n = int.from_bytes(fh.read(8), "little")
            if not 2 <= n <= min(path.stat().st_size - 8, 100 << 20):
                raise not_one
            head = fh.read(n)
    except OSError as e:
        raise VtsError(f"cannot read checkpoint ({e.strerror or e})", path) from None
    if head[:1] != b"{":
        raise not_one
    doc = loads(head, path, "checkpoint header")
    meta = doc.get("__metadata__") if isinstance(doc, dict) else None
    if not isinstance(meta, dict) or meta.get("recipe") != recipe:
        raise not_one
    out: dict[str, Any] = dict(meta)
    for key in json_keys:
        if not isinstance(meta.get(key), str):
            raise VtsError(f"corrupt {recipe} checkpoint (no {key!r} in its metadata)", path)
        out[key] = loads(meta[key], path, f"checkpoint metadata {key!r}")
    return out


def load_config(recipe: Any, path: str | Path | None) -> dict[str, Any]:
    """The recipe's default config updated by a JSON (or TOML) file; unknown keys are an error."""
    config = dict(recipe.default_config())
    if path is None:
        return config
    from .jsonio import loads, read_bytes

    path = Path(path)
    data = read_bytes(path, "config file", 16 << 20)
    if path.suffix == ".toml":
        import tomllib

        try:
            given = tomllib.loads(data.decode("utf-8"))
        except (ValueError, RecursionError) as e:
            raise VtsError(f"config is not valid TOML ({str(e)[:100]})", path) from None
    else:
        given = loads(data, path, "config JSON")
    if not isinstance(given, dict):
        raise VtsError("config must be a mapping of option names to values", path)
    unknown = sorted(set(given) - set(config))
    if unknown:
        raise VtsError(f"unknown config keys {unknown} (known: {sorted(config)})", path)
    nullable = getattr(recipe, "nullable", frozenset())
    for key, value in given.items():
        want = config[key]
        ok = (isinstance(value, type(want)) or want is None
              or (value is None and key in nullable)
              or (isinstance(want, float) and isinstance(value, int)))
        if not ok or (isinstance(value, bool) and want is not None
                      and not isinstance(want, bool)) or (
                isinstance(value, float) and not math.isfinite(value)):
            raise VtsError(f"config key {key!r}: expected a {type(want).__name__} like "
                           f"{want!r}, got {value!r}", path)
    config.update(given)
    return config


def write_submission(rows: Iterable[dict[str, Any]], out: str | Path, *, method: str,
                     dataset_path: str | Path, recipe: str | None = None,
                     seeds: list[int] | None = None, extra: dict[str, Any] | None = None
                     ) -> tuple[Path, Path]:
    """Write rows as a submission CSV and its metadata (OUT.meta.json) beside it."""
    from .dataset.loader import load
    from .evaluation.submission import default_meta_path

    rows = list(rows)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    extra_cols = sorted({k for r in rows for k in r if k not in ROW_COLUMNS},
                        key=lambda k: (not k.startswith("score_"), len(k), k))
    cols = [*ROW_COLUMNS, *extra_cols]
    from .atomic import replacing, write_text_atomic

    with replacing(out) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=cols)
        w.writeheader()
        for r in rows:
            w.writerow({c: r.get(c, "") for c in cols})
    info = load(dataset_path).info

    meta: dict[str, Any] = {"method": method, "recipe": recipe,
                            "dataset_version": info.dataset_version,
                            "dataset_sha256": info.dataset_sha256,
                            "vtsbench_version": _version()}
    if seeds is not None:
        meta["seeds"] = seeds
    meta.update(extra or {})
    meta_path = default_meta_path(out)
    write_text_atomic(meta_path, json.dumps(meta, indent=1, sort_keys=True) + "\n")
    return out, meta_path


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("vtsbench")
    except PackageNotFoundError:  # pragma: no cover - running from a bare checkout
        return "0+unknown"


def progress_iter(items: Iterable[Any], total: int, label: str, enabled: bool = True
                  ) -> Iterable[Any]:
    """Iterate with a progress display on stderr when enabled (a bar on a terminal, lines
    otherwise)."""
    if not enabled:
        yield from items
        return
    from .progress import progress_bar

    with progress_bar() as bar:
        task = bar.add_task(label, total=total)
        for item in items:
            yield item
            bar.advance(task)


def fit_view(dataset_path: str | Path, split: str, parts: Sequence[str] = ("train",)) -> Any:
    """The samples a recipe trains on: the union of `parts` of a split (default its `train`
    part; a final model may fold `val` in when nothing is selected on it). Never the test
    part, so that a leaderboard figure stays held out."""
    import numpy as np

    import vtsbench
    from vtsbench.dataset.loader import View

    if not parts:
        raise VtsError("fit_parts must name at least one part")
    if "test" in parts:
        raise VtsError("fit_parts may not include the test part")
    ds = vtsbench.load(dataset_path)
    views = [ds.split(split, p) for p in parts]
    if len(views) == 1:
        return views[0]
    pos = np.unique(np.concatenate([v._pos for v in views]))
    return View(ds, views[0].kind, pos)
