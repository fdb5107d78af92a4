"""`vtsbench preview`: a contact sheet of frames with their labels, and true depth when known."""

from __future__ import annotations

import math
import random
from pathlib import Path

from ..errors import VtsError
from ..figures import plain_text
from ..labels import DIRECTION_NAMES
from .manifest import Entry, Manifest, load_manifest
from .media import read_frame
from .truth import read_truth


def pick_entries(m: Manifest, n: int, seed: int = 0) -> list[Entry]:
    """n entries spread over kinds and sequence states (round robin), reproducibly."""
    groups: dict[str, list[Entry]] = {}
    for e in m.entries:
        key = e.kind if e.kind != "sequence" else f"sequence/{e.labels.state}"
        groups.setdefault(key, []).append(e)
    rng = random.Random(seed)
    pools = [rng.sample(v, len(v)) for _, v in sorted(groups.items())]
    out: list[Entry] = []
    while len(out) < n and any(pools):
        for pool in pools:
            if pool and len(out) < n:
                out.append(pool.pop())
    return out


def _shown_frame(e: Entry) -> tuple[int, int]:
    """(frame index in the source, index within the entry) of the frame to show."""
    s = e.source
    if e.kind != "sequence":
        return (s.frame or 0), 0
    start = s.start or 0
    if s.stop is None:
        return start, 0
    k = (s.stop - start) - 1  # last frame: the end of a press or slip shows most
    return start + k, k


def _caption(e: Entry) -> str:
    lab = e.labels
    parts = [e.id, e.kind if e.kind != "sequence" else f"seq: {lab.state or '?'}"]
    if e.object:
        parts.append(e.object)
    if lab.direction is not None:
        parts.append(f"dir {lab.direction} ({DIRECTION_NAMES[lab.direction]})")
    if lab.press_depth_mm is not None:
        parts.append(f"{lab.press_depth_mm:.2f} mm")
    if e.ball_radius_mm is not None:
        parts.append(f"ball R {e.ball_radius_mm:g} mm")
    return "\n".join([" | ".join(parts[:2]), " | ".join(parts[2:])])


@plain_text
def write_preview(folder: str | Path, out: str | Path, n: int = 12, seed: int = 0) -> int:
    """Render up to n entries of a recordings folder to a PNG contact sheet; returns how many."""
    if Path(out).is_dir():
        raise VtsError("is a folder; --out takes the name of the PNG to write", out)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..figures import MIN_FONT_PT, save_png

    folder, out = Path(folder), Path(out)
    m = load_manifest(folder)
    entries = pick_entries(m, n, seed)
    if not entries:
        raise VtsError("no entries to preview", folder / "recordings.json")
    with_truth = any(e.truth for e in entries)
    per = 2 if with_truth else 1
    cols = max(1, min(4, len(entries)))
    rows = math.ceil(len(entries) / cols)
    fig, axes = plt.subplots(rows, cols * per, figsize=(3.2 * cols * per, 2.9 * rows),
                             squeeze=False)
    for ax in axes.flat:
        ax.axis("off")
    for i, e in enumerate(entries):
        r, c = divmod(i, cols)
        ax = axes[r][c * per]
        src_idx, k = _shown_frame(e)
        rgb = read_frame(folder / e.source.path, src_idx)
        ax.imshow(rgb)
        ax.set_title(_caption(e), fontsize=MIN_FONT_PT)
        _draw_overlays(ax, e, rgb.shape)
        if with_truth:
            dax = axes[r][c * per + 1]
            if e.truth:
                depth = read_truth(folder / e.truth).depth_mm[k]
                im = dax.imshow(depth, cmap="viridis", vmin=0.0, vmax=max(float(depth.max()), 1e-3))
                cb = fig.colorbar(im, ax=dax, fraction=0.035, pad=0.02)
                cb.ax.tick_params(labelsize=MIN_FONT_PT)
                dax.set_title("true depth (mm)", fontsize=MIN_FONT_PT)
    fig.suptitle(f"{folder.name}: {len(m.entries)} entries, {len(m.sessions)} session(s)",
                 fontsize=11)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    save_png(fig, out)
    return len(entries)


def _draw_overlays(ax, e: Entry, shape: tuple[int, ...]) -> None:
    """Slip arrow (image frame: y up, so rows go the other way) and press circle."""
    h, w = shape[:2]
    mot = e.labels.motion_mm
    if e.labels.state == "slip" and mot is not None and any(mot):
        ang = math.atan2(mot[1], mot[0])
        L = 0.2 * min(h, w)
        ax.annotate("", xy=(w / 2 + L * math.cos(ang), h / 2 - L * math.sin(ang)),
                    xytext=(w / 2, h / 2),
                    arrowprops={"arrowstyle": "-|>", "color": "red", "lw": 1.5})
    if e.circle is not None:
        import matplotlib.patches as mpatches

        ax.add_patch(mpatches.Circle((e.circle.x, e.circle.y), e.circle.r, fill=False,
                                     color="red", lw=0.8))
