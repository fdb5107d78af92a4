"""Moved to vtsbench.depth.depthmaps; re-exported here so that imports of the old path keep
working."""

from ..depth.depthmaps import _ONES, CONTACT_PARAMS, DepthMaker

__all__ = [
    "CONTACT_PARAMS",
    "_ONES",
    "DepthMaker",
]
