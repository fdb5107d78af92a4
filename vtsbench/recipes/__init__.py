"""Recipes: a baseline that trains on a dataset split and writes a submission `vtsbench eval`
accepts.

A recipe is an object with `name`, `tasks`, `default_config()`, `train(...)` and
`predict(...)` (the `Recipe` base class in `base.py` documents the contract). It is found by
`load_recipe(name_or_path)` (`registry.py`): a path to a Python file that defines `RECIPE`, or a
name registered under the entry-point group `vtsbench.recipes` (the built-in ones live in
`vtsbench.recipes.builtin`). A recipe uses vtsbench's public API only: `vtsbench.load`, views,
`to_torch`, `vtsbench.training`, `vtsbench.transforms` and `vtsbench.labels`.

This package re-exports the names recipes and the command line use.
"""

from .base import Recipe
from .checkpoints import check_checkpoint, checkpoint_meta
from .config import load_config
from .data import fit_view, iter_items, iter_samples, per_read, progress_iter, read_items
from .registry import ENTRY_POINT_GROUP, guarded, load_recipe, registered
from .submission import ROW_COLUMNS, write_submission

__all__ = ["ENTRY_POINT_GROUP", "ROW_COLUMNS", "Recipe", "check_checkpoint", "checkpoint_meta",
           "fit_view", "guarded", "iter_items", "iter_samples", "load_config", "load_recipe",
           "per_read", "progress_iter", "read_items", "registered", "write_submission"]
