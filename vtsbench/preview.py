"""Old path of `vtsbench.recordings.preview` (`vtsbench preview`), kept for existing imports."""

from .recordings.preview import pick_entries, write_preview

__all__ = ["pick_entries", "write_preview"]
