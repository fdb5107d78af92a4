"""Old path of `vtsbench.recordings.collect` (`vtsbench collect`), kept for existing imports."""

from .recordings.collect import (
    BACKGROUND_NAME,
    CONTACT_AREA,
    CONTACT_BLUR_PX,
    CONTACT_LEVEL,
    DEFAULT_BACKGROUND_FRAMES,
    DEFAULT_EVERY,
    DEFAULT_WINDOW,
    FRAME_NAME,
    ID_RE,
    MODES,
    CollectOptions,
    CollectResult,
    collect,
    contact_fraction,
    frame_labels,
    frame_time,
    median_background,
    window_labels,
)

__all__ = ["BACKGROUND_NAME", "CONTACT_AREA", "CONTACT_BLUR_PX", "CONTACT_LEVEL",
           "DEFAULT_BACKGROUND_FRAMES", "DEFAULT_EVERY", "DEFAULT_WINDOW", "FRAME_NAME", "ID_RE",
           "MODES", "CollectOptions", "CollectResult", "collect", "contact_fraction",
           "frame_labels", "frame_time", "median_background", "window_labels"]
