"""Sensor optics: three-zone RGB illumination of a matte coating, vignetting and camera noise.

The per-sensor fields (light direction and gain of every LED zone at every pixel, vignetting,
the noise-free flat image) depend only on the frame size and scale, so they are computed once
per process and cached; a frame then shades only the pixels whose surface is not flat.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

#: Azimuths (deg, counter-clockwise from image right, y up) of the R, G and B LED zones.
LED_AZIMUTH_DEG = (90.0, 210.0, 330.0)
#: LED zones sit on an ellipse this many half-widths/half-heights from the centre (the border).
LED_RADIUS = 1.3
#: Height of the LED zones above the coating, as a fraction of the frame's half-diagonal.
LED_HEIGHT = 0.6
#: A zone's irradiance on the flat coating falls as (d0 / d)^FALLOFF with the distance d from
#: the zone (d0 at the frame centre): an extended strip seen through the light guide, softer
#: than a point source's inverse square.
FALLOFF = 0.8
#: Channel response to each zone: rows R, G, B camera channels; columns R, G, B LED zones.
CROSSTALK = np.array([[1.00, 0.10, 0.06],
                      [0.08, 1.00, 0.10],
                      [0.05, 0.12, 1.00]])
CROSSTALK_F32 = CROSSTALK.astype(np.float32)
#: Flat-coating level (DN) of each channel at the frame centre, without vignetting.
FLAT_LEVEL = np.array([156.0, 150.0, 160.0])
#: Share of the flat level that comes from ambient (non-directional) light.
AMBIENT_SHARE = 0.15
#: Vignetting: brightness (1 + (r / VIGNETTE_R)^2)^-2, r relative to the half-diagonal.
VIGNETTE_R = 2.2
#: Shot noise: variance in DN^2 per DN of signal (a gain of 25 electrons per DN).
SHOT_VAR_PER_DN = 0.04


@dataclass(frozen=True)
class Capture:
    """Camera settings of one session: read noise (DN), exposure (a gain on the signal) and
    the gel the sensor wears (its number draws a version-2 scene's fixed gel pattern)."""

    read_noise: float = 1.5
    exposure: float = 1.0
    gel: int = 0


@dataclass(frozen=True, eq=False)
class Sensor:
    """Cached per-pixel fields of one sensor geometry."""

    height: int
    width: int
    mm_per_px: float
    light: np.ndarray  # (3 zones, 3 xyz, H, W) float32: unit vector from the pixel to the zone
    gain: np.ndarray  # (3 zones, H, W) float32: vignetting * zone gain per unit of n.L
    ambient: np.ndarray  # (H, W, 3 channels) float32
    flat: np.ndarray  # (H, W, 3 channels) float32, noise-free image of the undeformed coating

    def shade(self, p: np.ndarray, q: np.ndarray, rows: slice, cols: slice) -> np.ndarray:
        """Noise-free RGB (h, w, 3) float32 of the surface with slopes p = dD/dx, q = dD/dy."""
        import cv2

        p = p.astype(np.float32)
        q = q.astype(np.float32)
        inv = p * p
        inv += q * q
        inv += 1.0
        np.sqrt(inv, out=inv)
        np.divide(1.0, inv, out=inv)
        zones = []
        for k in range(3):
            lx, ly, lz = (self.light[k, i, rows, cols] for i in range(3))
            # n.L for the surface z = D(x, y) seen from the camera: n = (-p, -q, 1) / |.|.
            s = lz - p * lx
            s -= q * ly
            np.maximum(s, 0.0, out=s)
            s *= inv
            s *= self.gain[k, rows, cols]
            zones.append(s)
        out = cv2.transform(cv2.merge(zones), CROSSTALK_F32)  # channels = CROSSTALK @ zones
        out += self.ambient[rows, cols]
        return out


def _fields(height: int, width: int, mm_per_px: float, vignetting: bool,
            nonuniform: bool) -> Sensor:
    """Compute light directions, gains, vignetting and the flat image of a sensor."""
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float64)
    cx, cy = (width - 1) / 2.0, (height - 1) / 2.0
    x = (xs - cx) * mm_per_px
    y = (ys - cy) * mm_per_px
    half_w, half_h = width * mm_per_px / 2.0, height * mm_per_px / 2.0
    half_diag = math.hypot(half_w, half_h)
    if not nonuniform:  # every pixel sees the zones as the centre does
        x = np.zeros_like(x)
        y = np.zeros_like(y)
    light = np.empty((3, 3, height, width), np.float32)
    gain = np.empty((3, height, width))
    for k, az in enumerate(LED_AZIMUTH_DEG):
        a = math.radians(az)
        # Zone position in pixel-frame mm (y down the rows, so the y-up azimuth flips sign).
        px, py, pz = (LED_RADIUS * half_w * math.cos(a), -LED_RADIUS * half_h * math.sin(a),
                      LED_HEIGHT * half_diag)
        dx, dy, dz = px - x, py - y, np.full_like(x, pz)
        dist = np.sqrt(dx * dx + dy * dy + dz * dz)
        light[k, 0], light[k, 1], light[k, 2] = dx / dist, dy / dist, dz / dist
        d0 = math.sqrt(px * px + py * py + pz * pz)
        # Gain per unit of n.L, so that the flat coating (n.L = lz) receives (d0 / d)^FALLOFF.
        gain[k] = (d0 / dist) ** FALLOFF * (pz / d0) / (dz / dist)
    # Scale the zones so that the flat coating at the centre reads FLAT_LEVEL in each channel.
    ic, jc = height // 2, width // 2
    direct0 = (1.0 - AMBIENT_SHARE) * FLAT_LEVEL
    lit0 = gain[:, ic, jc] * light[:, 2, ic, jc]
    gain *= np.linalg.solve(CROSSTALK * lit0[None, :], direct0)[:, None, None]
    if vignetting:
        r2 = ((xs - cx) ** 2 + (ys - cy) ** 2) * (mm_per_px / half_diag) ** 2
        vig = (1.0 + r2 / VIGNETTE_R**2) ** -2
    else:
        vig = np.ones((height, width))
    gain *= vig[None]
    ambient = (vig[..., None] * (AMBIENT_SHARE * FLAT_LEVEL)[None, None, :]).astype(np.float32)
    s = Sensor(height, width, mm_per_px, light, gain.astype(np.float32), ambient, ambient)
    flat = s.shade(np.zeros((height, width)), np.zeros((height, width)), slice(None), slice(None))
    return dataclasses.replace(s, flat=flat)


@lru_cache(maxsize=4)
def sensor(height: int, width: int, mm_per_px: float, vignetting: bool = True,
           nonuniform: bool = True) -> Sensor:
    """The sensor fields for a frame size and scale, computed once per process."""
    return _fields(height, width, mm_per_px, vignetting, nonuniform)


@lru_cache(maxsize=1)
def _normal_lut() -> np.ndarray:
    """256 equiprobable quantiles of the standard normal, scaled to unit variance."""
    from scipy.special import ndtri

    lut = ndtri((np.arange(256) + 0.5) / 256.0)
    return (lut / lut.std()).astype(np.float32).reshape(1, 256)


def normal_field(rng: np.random.Generator, height: int, width: int) -> np.ndarray:
    """Unit-variance noise (H, W, 3) float32 drawn from rng.

    Measured on this project's 2-core AMD EPYC (numpy 2.4, 921,600 values per frame):
    rng.standard_normal(dtype=float32) 9.0 ms; rng.bytes + cv2.LUT into 256 normal quantiles
    0.94 ms (np.take 1.4 ms; 65,536 quantiles from 16-bit draws 2.3 ms). The quantised normal
    is kept: its tails stop at 2.9 sigma, which is invisible after rounding to 8 bits.
    """
    import cv2

    raw = np.frombuffer(rng.bytes(height * width * 3), np.uint8).reshape(height, width, 3)
    return cv2.LUT(raw, _normal_lut())


@lru_cache(maxsize=8)
def _flat_sigma(s: Sensor, capture: Capture) -> tuple[np.ndarray, np.ndarray]:
    """Flat image and its noise standard deviation for a session's capture settings."""
    flat = (s.flat * np.float32(capture.exposure)).astype(np.float32)
    return flat, noise_sigma(flat, capture)


def noise_sigma(signal: np.ndarray, capture: Capture) -> np.ndarray:
    """Per-pixel noise standard deviation (DN): read noise plus shot noise."""
    var = np.maximum(signal, 0.0) * np.float32(SHOT_VAR_PER_DN)
    var += np.float32(capture.read_noise**2)
    return np.sqrt(var, out=var)


def capture_frame(s: Sensor, capture: Capture, rng: np.random.Generator | None,
                  patch: np.ndarray | None = None, rows: slice = slice(0, 0),
                  cols: slice = slice(0, 0)) -> np.ndarray:
    """Camera frame (H, W, 3) uint8: the flat image with `patch` pasted at (rows, cols), noise.

    `patch` is the noise-free exposure-free signal of the shaded region; rng None means no noise.
    """
    flat, sigma = _flat_sigma(s, capture)
    if rng is None:
        out = flat.copy()
        if patch is not None:
            out[rows, cols] = patch * np.float32(capture.exposure)
    else:
        n = normal_field(rng, s.height, s.width)
        out = sigma * n
        out += flat
        if patch is not None:
            sig = patch * np.float32(capture.exposure)
            noisy = noise_sigma(sig, capture)
            noisy *= n[rows, cols]
            noisy += sig
            out[rows, cols] = noisy
    out += 0.5
    np.clip(out, 0.0, 255.0, out=out)
    return out.astype(np.uint8)
