"""What a real sensor's camera shows besides the imprint: the gel's fixed pattern and the camera.

`Appearance` holds the options of a version-2 scene; its defaults are measured on GelSight Mini
videos (docs/simulator.md, "Generator 2: the sensor's appearance"). `capture` turns the shaded
patches of a scene's frames into camera frames; `background` gives a session's no-contact frame
with the same gel pattern.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .optics import Capture, Sensor


@dataclass(frozen=True)
class Appearance:
    """Gel pattern, imprint contrast and camera options of a version-2 scene.

    The pattern and the imprint gain belong to the gel (drawn from `pattern_seed` and the
    capture's gel number); the camera's ranges (lo, hi) are drawn uniformly per scene. A
    simulated folder's sensor is `sensor_appearance(gel)`: these defaults with the options of
    its gel (`GEL_OPTIONS`).
    """

    # The gel's fixed pattern.
    pattern_seed: int = 0
    marker_share: float = 0.5  # share of gels with a printed marker grid
    marker_pitch_mm: float = 2.77  # grid spacing (43.7 px at 0.0634 mm/px)
    marker_diameter_mm: float = 1.13  # dot diameter at half depth (17.8 px)
    marker_darkness: float = 0.75  # share of the light a dot's centre absorbs
    marker_edge_mm: float = 0.15  # width of a dot's soft edge
    marker_jitter_mm: float = 0.02  # print jitter of the dot centres (sd)
    border_mm: float = 0.5  # the edge band at full darkness...
    border_ramp_mm: float = 0.75  # ...then fading to clear over this width
    border_darkness: tuple[float, float] = (0.02, 0.10)  # per side
    dust_per_cm2: float = 2.3  # specks on the gel surface
    dust_diameter_mm: tuple[float, float] = (0.06, 0.3)
    dust_darkness: tuple[float, float] = (0.04, 0.12)
    scratches: int = 2  # at most this many per gel
    scratch_length_mm: tuple[float, float] = (1.0, 4.0)
    scratch_width_mm: float = 0.04
    grain: float = 0.006  # relative sd of the coating's fine grain (per pixel, rides the gel)
    # The imprint: a gel's gain on the shaded imprint's deviation from the flat image.
    imprint_gain: tuple[float, float] = (0.25, 1.0)
    # The camera.
    noise_scale: float = 0.55  # on the session's read and shot noise
    jpeg_quality: tuple[int, int] | None = (60, 90)  # None: no compression
    skip_dn: float = 2.5  # a block is re-sent when a 4x4 cell's grey changed by more
    refresh: float = 0.15  # share of the other blocks re-sent anyway, per frame
    keyframe_interval: int | None = 12  # a whole frame is sent every this many (None: never)
    wb_jump_share: float = 0.05  # share of scenes that start a stream
    wb_jump_gain: tuple[tuple[float, float], ...] = ((0.85, 0.98), (0.65, 0.97), (0.65, 0.97))
    wb_settle_gain: tuple[float, float] = (0.97, 1.0)  # the second frame of such a scene
    drift: float = 0.002  # each channel's gain moves by at most this over a scene


#: The simulated sensor's gel: a printed marker grid, or plain (border, dust and scratches).
GELS = ("markers", "plain")
DEFAULT_GEL = "plain"
#: What differs between the two gels: the marker grid, the imprint gain range (a folder draws
#: one gain in it from its seed) and the coating's grain, from the imprint and off-contact
#: high-pass RMS of the real marker-gel and markerless clips (docs/simulator.md).
GEL_OPTIONS: dict[str, dict] = {
    "markers": {"marker_share": 1.0, "imprint_gain": (0.7, 0.9), "grain": 0.006},
    "plain": {"marker_share": 0.0, "imprint_gain": (0.3, 0.4), "grain": 0.016},
}


def sensor_appearance(gel: str = DEFAULT_GEL) -> Appearance:
    """The appearance of a simulated sensor wearing a marker gel or a plain one."""
    if gel not in GELS:
        raise ValueError(f"gel must be one of {', '.join(GELS)}, got {gel!r}")
    return Appearance(**GEL_OPTIONS[gel])


def capture(app: Appearance, fields: Sensor, cap: Capture, rng: np.random.Generator | None,
            shots: list[tuple[np.ndarray | None, slice, slice]],
            surface_px: np.ndarray | None) -> np.ndarray:
    """Camera frames (T, H, W, 3) uint8 of a scene from its noise-free shaded patches
    `shots` (patch, rows, cols per frame) and the gel surface displacement (T, H, W, 2)."""
    from .camera import compress, draw_take, expose
    from .pattern import gel_pattern, layer_at

    pattern = gel_pattern(app, cap.gel, fields.height, fields.width, fields.mm_per_px)
    take = draw_take(app, rng, len(shots), cap.gel)
    frames = np.empty((len(shots), fields.height, fields.width, 3), np.uint8)
    layer, moved = pattern.still, None
    for t, (patch, rows, cols) in enumerate(shots):
        if surface_px is not None and not (t and np.array_equal(surface_px[t],
                                                                surface_px[t - 1])):
            layer, moved = layer_at(pattern, surface_px[t])
        frames[t] = expose(fields, cap, app, take, t, rng, patch, rows, cols, pattern, layer,
                           moved)
    return compress(frames, take.quality, app.skip_dn, app.refresh, rng, take.keyframes)


def background(app: Appearance, fields: Sensor, cap: Capture,
               rng: np.random.Generator | None) -> np.ndarray:
    """A session's no-contact frame (H, W, 3) uint8: the gel pattern, noise, compression; no
    channel jump or drift."""
    from .camera import Take, compress, draw_take, expose
    from .pattern import gel_pattern

    pattern = gel_pattern(app, cap.gel, fields.height, fields.width, fields.mm_per_px)
    drawn = draw_take(app, rng, 1, cap.gel)
    take = Take(drawn.imprint_gain, drawn.quality, np.ones((1, 3), np.float32), ())
    frame = expose(fields, cap, app, take, 0, rng, None, slice(0, 0), slice(0, 0), pattern,
                   pattern.still, None)
    return compress(frame[None], take.quality, app.skip_dn)[0]
