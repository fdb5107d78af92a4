"""Moved to vtsbench.dataset.tools.info; re-exported here so that imports of the old path keep
working."""

from .tools.info import Summary, human, render, summarise

__all__ = [
    "Summary",
    "human",
    "render",
    "summarise",
]
