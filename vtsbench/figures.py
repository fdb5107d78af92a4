"""Figures at print quality: one resolution, one smallest text size, one way to save.

Every matplotlib figure the package writes (evaluation confusion matrices, the contact sheet,
the calibration report) is drawn under `print_style()` and written by `save_png`: PNG at
PRINT_DPI, rendered in memory and written atomically. Text is never below MIN_FONT_PT.
"""

from __future__ import annotations

import contextlib
import functools
import io
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

#: Resolution of every PNG figure (print quality: 150 dpi or more).
PRINT_DPI = 150
#: The smallest text size in a figure, in points.
MIN_FONT_PT = 9.0

#: Text is drawn as written: sensor ids, object and folder names are the user's, and a '$' in
#: one would start matplotlib's TeX, which raises on what it cannot parse ('gs$\\frac{a$mini'
#: as a sensor id failed the calibration report with a traceback).
PLAIN_TEXT = {"text.parse_math": False}

#: matplotlib settings of print_style: every text element at MIN_FONT_PT or more.
STYLE = {**PLAIN_TEXT, "font.size": 10.0, "axes.titlesize": 10.0, "axes.labelsize": 10.0,
         "xtick.labelsize": MIN_FONT_PT, "ytick.labelsize": MIN_FONT_PT,
         "legend.fontsize": MIN_FONT_PT, "figure.titlesize": 11.0,
         "figure.dpi": PRINT_DPI, "savefig.dpi": PRINT_DPI}


@contextlib.contextmanager
def print_style() -> Iterator[None]:
    """matplotlib's rc settings for a printed figure (STYLE) inside the block."""
    import matplotlib

    with matplotlib.rc_context(STYLE):
        yield


def plain_text(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Decorator: the figures drawn inside `fn` show their text as written (PLAIN_TEXT)."""
    @functools.wraps(fn)
    def drawn(*args: Any, **kwargs: Any) -> Any:
        import matplotlib

        with matplotlib.rc_context(PLAIN_TEXT):
            return fn(*args, **kwargs)

    return drawn


def font_pt(size: float) -> float:
    """A text size for a figure: the requested size, never below MIN_FONT_PT."""
    return max(float(size), MIN_FONT_PT)


def png_bytes(fig: Any, dpi: int = PRINT_DPI) -> bytes:
    """The figure as PNG bytes at `dpi` (at least PRINT_DPI)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=max(dpi, PRINT_DPI))
    return buf.getvalue()


def save_png(fig: Any, path: str | Path, dpi: int = PRINT_DPI) -> Path:
    """Write the figure as a PNG atomically (complete or absent) and close it."""
    from .atomic import write_bytes_atomic

    path = Path(path)
    try:
        write_bytes_atomic(path, png_bytes(fig, dpi))
    finally:
        _close(fig)
    return path


def _close(fig: Any) -> None:
    """Release a pyplot figure (object-API figures need nothing)."""
    import sys

    plt = sys.modules.get("matplotlib.pyplot")
    if plt is not None:
        plt.close(fig)
