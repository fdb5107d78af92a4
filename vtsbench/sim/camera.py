"""A video camera's frames: imprint contrast, channel gains (start-of-stream jump, slow drift),
noise, and video compression in which still blocks are not re-sent.

Compression is OpenCV's JPEG (libjpeg) per frame, with the one trait of a video codec that
decides what a still sensor looks like: a 16 x 16 block is sent again only when its content
changed by more than `skip_dn` since it was last sent (grey level averaged over 4 x 4 pixels,
which keeps noise below it); otherwise the decoder keeps the previous frame's block, so still
pixels carry no fresh noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from .optics import Capture, Sensor, noise_sigma, normal_field

if TYPE_CHECKING:
    from .appearance import Appearance
    from .pattern import GelPattern

#: Block size (px) of the compression's send-or-keep decision.
BLOCK = 16
#: The change in a block is measured after averaging cells of CELL x CELL pixels.
CELL = 4


@dataclass(frozen=True)
class Take:
    """What one scene's camera draws: imprint gain, JPEG quality, channel gains per frame."""

    imprint_gain: float
    quality: int | None  # None: no compression
    gains: np.ndarray  # (T, 3) float32 per-channel gain of each frame
    keyframes: tuple[int, ...] = ()  # frames sent whole (the stream's key frames)


def gel_gain(app: Appearance, gel: int) -> float:
    """The imprint gain of gel number `gel`: log-evenly spread over `imprint_gain` along
    consecutive gel numbers (a golden-ratio sequence), so a few sessions cover the range."""
    lo, hi = app.imprint_gain
    phase = np.random.default_rng([app.pattern_seed, 3]).random()
    u = (gel * 0.6180339887498949 + phase) % 1.0
    return math.exp(math.log(lo) + u * (math.log(hi) - math.log(lo)))


def draw_take(app: Appearance, rng: np.random.Generator | None, n_frames: int,
              gel: int = 0) -> Take:
    """Draw a scene's compression quality, start-of-stream jump and drift (rng None: best
    quality, no jump, no drift); the imprint gain is the gel's."""
    gain = gel_gain(app, gel)
    gains = np.ones((n_frames, 3), np.float64)
    if rng is None:
        q = None if app.jpeg_quality is None else int(app.jpeg_quality[1])
        return Take(gain, q, gains.astype(np.float32))
    q = None if app.jpeg_quality is None else int(rng.integers(app.jpeg_quality[0],
                                                               app.jpeg_quality[1] + 1))
    keys: tuple[int, ...] = ()
    if app.keyframe_interval:  # the window starts anywhere in the stream's group of pictures
        phase = int(rng.integers(app.keyframe_interval))
        keys = tuple(t for t in range(1, n_frames) if (phase + t) % app.keyframe_interval == 0)
    jump = rng.random() < app.wb_jump_share
    first = np.array([rng.uniform(*r) for r in app.wb_jump_gain])
    second = rng.uniform(*app.wb_settle_gain, 3)
    drift = rng.uniform(-app.drift, app.drift, 3)
    if n_frames > 1:
        gains *= 1.0 + drift[None, :] * (np.arange(n_frames)[:, None] / (n_frames - 1))
        if jump:
            gains[0] *= first
            if n_frames > 2:
                gains[1] *= second
    return Take(gain, q, gains.astype(np.float32), keys)


@lru_cache(maxsize=8)
def _still(s: Sensor, capture: Capture, scale: float,
           pattern: GelPattern) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Flat image and its (scaled) noise sd for a session's capture, without and with the
    undisplaced gel pattern."""
    flat = (s.flat * np.float32(capture.exposure)).astype(np.float32)
    sigma = noise_sigma(flat, capture)
    sigma *= np.float32(scale)
    still = pattern.still[..., None]
    return flat, sigma, flat * still, sigma * still


def expose(s: Sensor, capture: Capture, app: Appearance, take: Take, t: int,
           rng: np.random.Generator | None, patch: np.ndarray | None, rows: slice,
           cols: slice, pattern: GelPattern, layer: np.ndarray,
           moved: tuple[slice, slice] | None) -> np.ndarray:
    """One frame (H, W, 3) uint8 before compression: the flat image with the imprint at the
    take's gain, read and shot noise, the gel pattern `layer` (differing from the still one
    inside `moved`) and the frame's channel gains. Outside the imprint and the moved box the
    cached flat and noise images with the still pattern are used."""
    import cv2

    flat, sigma, flat_l, sigma_l = _still(s, capture, app.noise_scale, pattern)
    n = None if rng is None else normal_field(rng, s.height, s.width)
    if n is None:
        out = flat_l.copy()
    else:
        out = sigma_l * n
        out += flat_l
    if moved is not None:  # the flat image's cached noise, under the moved pattern
        mr, mc = moved
        if n is None:
            sig = flat[mr, mc].copy()
        else:
            sig = sigma[mr, mc] * n[mr, mc]
            sig += flat[mr, mc]
        sig *= layer[mr, mc][..., None]
        out[mr, mc] = sig
    if patch is not None:  # the imprint: its own signal, so its own noise
        sig = patch * np.float32(capture.exposure)
        sig -= flat[rows, cols]
        sig *= np.float32(take.imprint_gain)
        sig += flat[rows, cols]
        if n is not None:
            noisy = noise_sigma(sig, capture)
            noisy *= np.float32(app.noise_scale)
            noisy *= n[rows, cols]
            sig += noisy
        sig *= layer[rows, cols][..., None]
        out[rows, cols] = sig
    g = take.gains[t]
    return cv2.multiply(out, (float(g[0]), float(g[1]), float(g[2]), 0.0), dtype=cv2.CV_8U)


def jpeg(frame: np.ndarray, quality: int, sampling: int | None = None) -> np.ndarray:
    """Encode and decode an RGB frame through OpenCV's JPEG at `quality`; sampling: OpenCV's
    IMWRITE_JPEG_SAMPLING_FACTOR (None: libjpeg's default, the colour at half resolution both
    ways, 4:2:0)."""
    import cv2

    params = [cv2.IMWRITE_JPEG_QUALITY, int(quality)]
    if sampling is not None:
        params += [cv2.IMWRITE_JPEG_SAMPLING_FACTOR, int(sampling)]
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(frame, cv2.COLOR_RGB2BGR), params)
    if not ok:  # pragma: no cover - libjpeg refuses only invalid arrays
        raise RuntimeError("JPEG encoding failed")
    return cv2.cvtColor(cv2.imdecode(buf, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)


def changed_blocks(frame: np.ndarray, sent: np.ndarray, skip_dn: float) -> np.ndarray:
    """(H, W) uint8 mask (1 = re-send): the 16 x 16 blocks where the mean grey level of some
    4 x 4 cell differs by more than skip_dn from what was last sent there (`sent`)."""
    import cv2

    h, w = frame.shape[:2]
    hp, wp = -(-h // BLOCK) * BLOCK, -(-w // BLOCK) * BLOCK
    diff = cv2.subtract(frame, sent, dtype=cv2.CV_32F)
    grey = cv2.transform(diff, np.full((1, 3), 1.0 / 3.0, np.float32))
    if (hp, wp) != (h, w):
        grey = cv2.copyMakeBorder(grey, 0, hp - h, 0, wp - w, cv2.BORDER_CONSTANT, value=0)
    cells = cv2.resize(grey, (wp // CELL, hp // CELL), interpolation=cv2.INTER_AREA)
    k = BLOCK // CELL
    big = np.abs(cells).reshape(hp // BLOCK, k, wp // BLOCK, k).max(axis=(1, 3))
    blocks = (big > skip_dn).astype(np.uint8)
    return cv2.resize(blocks, (wp, hp), interpolation=cv2.INTER_NEAREST)[:h, :w]


def compress(frames: np.ndarray, quality: int | None, skip_dn: float,
             refresh: float = 0.0, rng: np.random.Generator | None = None,
             keyframes: tuple[int, ...] = ()) -> np.ndarray:
    """Frames (T, H, W, 3) uint8 as a video codec returns them: JPEG at `quality`; a block is
    sent again when its content changed by more than skip_dn since it was last sent, or (with
    probability `refresh` per frame, drawn from rng) anyway; other blocks are kept from the
    previous decoded frame. The frames in `keyframes` (and the first) are sent whole."""
    if quality is None:
        return frames
    import cv2

    h, w = frames.shape[1:3]
    nby, nbx = -(-h // BLOCK), -(-w // BLOCK)
    out = np.empty_like(frames)
    sent = frames[0].copy()
    for t, frame in enumerate(frames):
        if t == 0 or t in keyframes:
            out[t] = jpeg(frame, quality)
            sent = frame.copy()
            continue
        mask = changed_blocks(frame, sent, skip_dn)
        if refresh > 0.0 and rng is not None:
            extra = (rng.random((nby, nbx)) < refresh).astype(np.uint8)
            extra = cv2.resize(extra, (nbx * BLOCK, nby * BLOCK),
                               interpolation=cv2.INTER_NEAREST)[:h, :w]
            mask |= extra
        out[t] = out[t - 1]
        if mask.any():
            cv2.copyTo(jpeg(frame, quality), mask, out[t])
            cv2.copyTo(frame, mask, sent)
    return out
