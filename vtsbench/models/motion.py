"""Moved to `vtsbench.transforms.motion`; this module re-exports it under the old path."""

from vtsbench.transforms.motion import *  # noqa: F403
