"""`plot(sample)` of the views (numpy and torch): RGB, depth and contact of one sample with its
labels, as a matplotlib Figure (no pyplot state: save it or show it in a notebook)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ...figures import plain_text
from ...labels import DIRECTION_NAMES, STATES


def labels_text(info: Any, class_idx: int | None, state_idx: int | None = None,
                direction: int | None = None, sample_id: str | None = None) -> str:
    """One line naming a sample's labels: id, object, and for slip its state and direction."""
    parts = [sample_id] if sample_id else []
    if class_idx is not None and 0 <= class_idx < len(info.objects):
        parts.append(f"object {info.objects[class_idx]} ({class_idx})")
    if state_idx is not None and 0 <= state_idx < len(STATES):
        parts.append(f"state {STATES[state_idx]}")
    if direction is not None and 0 <= direction < len(DIRECTION_NAMES):
        parts.append(f"direction {DIRECTION_NAMES[direction]} ({direction})")
    return ", ".join(parts)


@plain_text
def plot_arrays(rgb: np.ndarray | None, depth: np.ndarray | None, contact: np.ndarray | None,
                title: str) -> Any:
    """A Figure with one panel per array given: rgb (H, W, 3) uint8 or float in [0, 1],
    depth (H, W) in mm with a colour bar, contact (H, W) bool."""
    from matplotlib.figure import Figure

    panels = [(n, a) for n, a in (("rgb", rgb), ("depth (mm)", depth), ("contact", contact))
              if a is not None]
    fig = Figure(figsize=(4 * max(1, len(panels)), 3.6), layout="constrained")
    axes = fig.subplots(1, max(1, len(panels)), squeeze=False)[0]
    for ax, (name, a) in zip(axes, panels, strict=False):
        if name == "rgb":
            ax.imshow(a)
        elif name == "contact":
            ax.imshow(a, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
        else:
            im = ax.imshow(a, cmap="viridis")
            fig.colorbar(im, ax=ax, shrink=0.8)
        ax.set_title(name)
        ax.set_axis_off()
    fig.suptitle(title)
    return fig


def _frame(a: Any, frame: int, seq: bool) -> np.ndarray | None:
    if a is None:
        return None
    a = np.asarray(a)
    return a[frame] if seq else a


def plot_sample(sample: Mapping[str, Any], info: Any, frame: int = -1) -> Any:
    """A loader sample (`view[i]`): its arrays at one frame (slip) and its labels."""
    seq = sample.get("kind") == "slip"
    title = labels_text(info, sample.get("class_idx"), sample.get("state_idx"),
                        sample.get("direction"), sample.get("sample_id"))
    if seq:
        title += f" - frame {frame % info.frames_per_sequence}"
    return plot_arrays(_frame(sample.get("rgb"), frame, seq), _frame(sample.get("depth"), frame,
                                                                      seq),
                       _frame(sample.get("contact"), frame, seq), title)
