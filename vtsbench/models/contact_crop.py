"""Moved to `vtsbench.transforms.contact_crop` (the crop) and `vtsbench.transforms.cache`
(`CachedItems`); this module re-exports them under the old path."""

from vtsbench.transforms.cache import CachedItems  # noqa: F401
from vtsbench.transforms.contact_crop import *  # noqa: F403
from vtsbench.transforms.contact_crop import _grey  # noqa: F401
