"""Moved to `vtsbench.recipes.builtin.resnet`; this module re-exports it under the old path (the
registered entry point `vtsbench.recipes_builtin.resnet:RECIPE`)."""

from vtsbench.recipes.builtin.resnet import *  # noqa: F403
from vtsbench.recipes.builtin.resnet import _normalize, _Normalized  # noqa: F401
