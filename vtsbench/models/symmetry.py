"""Moved to `vtsbench.transforms.symmetry`; this module re-exports it under the old path."""

from vtsbench.transforms.symmetry import *  # noqa: F403
