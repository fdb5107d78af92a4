"""Building a dataset from recordings: the steps of `vtsbench build` (pipeline) and the modules
they use (options, plan, shard, execute, staging, finish, depthmaps, store, card, png).

The package also gives what the module `vtsbench.dataset.build` held before it became this
package (`build`, `BuildOptions`, `BuildResult`, `partial_path`, `WORK`), loaded from
`pipeline` on first use, so that importing one step (a worker's `shard`) stays light.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .pipeline import WORK, BuildOptions, BuildResult, build, partial_path

__all__ = ["WORK", "BuildOptions", "BuildResult", "build", "partial_path"]


def __getattr__(name: str) -> Any:
    """The names of the former module, from `pipeline` on first access."""
    if name in __all__:
        from . import pipeline

        return getattr(pipeline, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
