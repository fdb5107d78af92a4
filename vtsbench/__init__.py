"""vtsbench: benchmark toolkit for visuo-tactile sensing.

`vtsbench.load(path_or_url)` opens a built dataset and `vtsbench.create(path, ...)` writes
episodes into a new one; both are imported on first use so that `import vtsbench` stays light
(no zarr, pyarrow or torch).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .dataset.build.writer import create
    from .dataset.read.loader import load

__all__ = ["create", "load"]


def __getattr__(name: str) -> Any:
    """Lazy attributes: `load` imports the dataset loader, `create` the episode writer, on
    first access."""
    if name == "load":
        from .dataset.read.loader import load

        return load
    if name == "create":
        from .dataset.build.writer import create

        return create
    raise AttributeError(f"module 'vtsbench' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *__all__])
