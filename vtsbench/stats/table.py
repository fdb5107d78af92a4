"""The statistics as a table, one column per folder, with a plain line for what a folder lacks
(no contact, no moving windows) instead of rows of undefined numbers."""

from __future__ import annotations

from typing import Any

from .summary import DISTRIBUTIONS, SHARES, FolderStats
from .window import CONTACT_DN, MIN_CONTACT_SHARE, MOVING_PX


def notes(f: FolderStats) -> list[str]:
    """One line per thing the folder's windows lack, and the windows counted."""
    out = [f"{f.folder}: {f.n_sampled} of {f.n_windows} windows of {f.frames_per_window} frames "
           f"measured: {f.n_moving} moving, {f.n_static} static"]
    if not f.n_contact:
        out.append(f"{f.folder}: no contact in any window (no frame differs from the reference by "
                   f"more than {CONTACT_DN:g} DN over {100 * MIN_CONTACT_SHARE:g} % of the frame): "
                   "only noise and texture off the contact are measured")
    elif not f.n_moving:
        out.append(f"{f.folder}: no moving windows (the contact's median displacement is never "
                   f"above {MOVING_PX:g} px): motion statistics are not defined")
    return out


def cell_distribution(d: Any) -> str:
    """'median [q25-q75]', or '-' when undefined."""
    if d.n == 0 or d.median is None:
        return "-"
    return f"{_num(d.median)} [{_num(d.q25)}-{_num(d.q75)}]"


def cell_share(s: Any) -> str:
    """'12 % of n', or '-' when undefined."""
    if s.n == 0 or s.share is None:
        return "-"
    return f"{100 * s.share:.0f} % of {s.n}"


def _num(v: float) -> str:
    return f"{v:.2f}" if abs(v) < 10 else f"{v:.1f}"


def rows(folders: list[FolderStats]) -> list[tuple[str, ...]]:
    """(statistic, one cell per folder) for every statistic defined in at least one folder."""
    out = []
    for name, (label, unit) in DISTRIBUTIONS.items():
        ds = [f.distributions[name] for f in folders]
        if any(d.n for d in ds):
            text = f"{label} ({unit})" if unit else label
            out.append((text, *(cell_distribution(d) for d in ds)))
    for name, (label, _) in SHARES.items():
        ss = [f.shares[name] for f in folders]
        if any(s.n for s in ss):
            out.append((label, *(cell_share(s) for s in ss)))
    return out


def print_stats(folders: list[FolderStats], console: Any) -> None:
    """Print the notes and, when anything is defined, the table (medians [quartiles])."""
    from rich.markup import escape
    from rich.table import Table

    for f in folders:
        for line in notes(f):
            console.print(escape(line), soft_wrap=True)
    body = rows(folders)
    if not body:
        return
    table = Table(title=escape("per window: median [quartiles]; shares of moving windows"))
    table.add_column("statistic")
    for f in folders:
        table.add_column(escape(f.folder), justify="right")
    for r in body:
        table.add_row(*(escape(c) for c in r))
    console.print(table)
