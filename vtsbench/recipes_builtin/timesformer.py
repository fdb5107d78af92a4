"""Moved to `vtsbench.recipes.builtin.timesformer`; this module re-exports it under the old
path (the registered entry point `vtsbench.recipes_builtin.timesformer:RECIPE`)."""

from vtsbench.recipes.builtin.timesformer import *  # noqa: F403
from vtsbench.recipes.builtin.timesformer import _frames, _normalize  # noqa: F401
