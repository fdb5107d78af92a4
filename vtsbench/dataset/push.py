"""Moved to vtsbench.dataset.tools.push; re-exported here so that imports of the old path keep
working."""

from .tools.push import IGNORE, PushPlan, check_repo_id, push, push_plan

__all__ = [
    "IGNORE",
    "PushPlan",
    "check_repo_id",
    "push",
    "push_plan",
]
