"""Moved to `vtsbench.recipes.builtin.flow`; this module re-exports it under the old path (the
registered entry point `vtsbench.recipes_builtin.flow:RECIPE`)."""

from vtsbench.recipes.builtin.flow import *  # noqa: F403
from vtsbench.recipes.builtin.flow import _gray, _Tree  # noqa: F401
