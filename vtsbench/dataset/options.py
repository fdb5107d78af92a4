"""Moved to vtsbench.dataset.build.options; re-exported here so that imports of the old path keep
working."""

from .build.options import SOLVERS, BuildOptions, check_options

__all__ = [
    "SOLVERS",
    "BuildOptions",
    "check_options",
]
