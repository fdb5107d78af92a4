"""How every check of a dataset words what it finds: one line per kind of problem, with a count
and the first few offenders, so a split of a million unknown ids is one line."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

#: Offenders shown in one problem line.
SHOWN = 3


def short(v: Any, n: int = 60) -> Any:
    """A string cut to n characters and '...'; any other value as it is."""
    return v[:n] + "..." if isinstance(v, str) and len(v) > n else v


def first(values: Sequence[Any]) -> str:
    """The first few values, quoted; '...' when there are more."""
    shown = ", ".join(repr(short(v)) for v in list(values[:SHOWN]))
    return shown + (", ..." if len(values) > SHOWN else "")


def rows(mask: np.ndarray, ids: Sequence[str], what: str,
         detail: Callable[[int], Any] | None = None) -> list[str]:
    """One line for the rows where mask holds: how many, and the first few by sample id."""
    hit = np.flatnonzero(mask)
    if not len(hit):
        return []
    shown = ", ".join(f"{short(ids[i])}" + (f" ({detail(i)})" if detail else "")
                      for i in hit[:SHOWN])
    more = ", ..." if len(hit) > SHOWN else ""
    return [f"{what} in {len(hit)} row(s) (first: {shown}{more})"]
