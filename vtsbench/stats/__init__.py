"""`vtsbench stats`: motion and appearance statistics of a recordings folder's windows, to see
how far one sensor (or the simulator) is from another."""

from __future__ import annotations

from pathlib import Path

from .summary import FolderStats, summarise, write_report


def folder_stats(folder: str | Path, window: int = 8, max_windows: int = 200,
                 progress: bool = False) -> FolderStats:
    """The summarised statistics of at most max_windows windows of a recordings folder."""
    from .folder import measure

    chosen, total, stats = measure(Path(folder), window, max_windows, progress)
    return summarise(Path(folder), chosen, total, stats)


def run_stats(folder: Path, compare: Path | None = None, out: Path | None = None,
              window: int = 8, max_windows: int = 200, progress: bool = False
              ) -> list[FolderStats]:
    """`vtsbench stats`: one or two folders' statistics, written to `out` as JSON if given."""
    folders = [folder_stats(f, window, max_windows, progress)
               for f in (folder, compare) if f is not None]
    if out is not None:
        write_report(out, folders)
    return folders


__all__ = ["FolderStats", "folder_stats", "run_stats"]
