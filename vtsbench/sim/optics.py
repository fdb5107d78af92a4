"""Sensor optics: LED illumination of a matte coating, vignetting and camera noise.

The light layout (`Lights`) says where each LED zone sits and what each camera channel sees of
it; the default is three coloured zones at azimuths 90/210/330 deg (`LIGHTS["zones3"]`), and the
presets add red, green, blue and white from four sides (`"sides4"`) and near-uniform diffuse
light (`"uniform"`), where the shading contrast is weak. The per-sensor fields (light direction
and gain of every zone at every pixel, vignetting, the noise-free flat image) depend only on the
frame size, scale and layout, so they are computed once per process and cached; a frame then
shades only the pixels whose surface is not flat. `vtsbench.sim.relight` shoots a rendered
scene's exact gradients through another layout.
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
class Light:
    """One LED zone: its azimuth (deg, counter-clockwise from image right, y up), what the R, G
    and B camera channels see of its light, and where it sits (see LED_RADIUS, LED_HEIGHT)."""

    azimuth_deg: float
    colour: tuple[float, float, float]
    radius: float = LED_RADIUS
    height: float = LED_HEIGHT
    falloff: float = FALLOFF


@dataclass(frozen=True)
class Lights:
    """A sensor's light layout: its LED zones and the share of the flat level that is ambient
    (non-directional) light.

    The flat coating at the frame centre reads FLAT_LEVEL in each channel: with three zones of
    independent colours by each zone's power (solved), otherwise by zones of equal power and the
    camera's gain per channel (its white balance)."""

    name: str
    zones: tuple[Light, ...]
    ambient_share: float = AMBIENT_SHARE

    @property
    def mix(self) -> np.ndarray:
        """(3 channels, zones) float64: each channel's response to each zone."""
        return np.array([z.colour for z in self.zones], np.float64).T


_RED, _GREEN, _BLUE = (tuple(float(v) for v in CROSSTALK[:, k]) for k in range(3))
#: The light layouts by name. zones3: three coloured zones at the border (GelSight-type, the
#: default); sides4: red, green, blue and white strips on the four sides, lower over the gel
#: (stronger shading); uniform: eight white zones high above the gel and half the light ambient
#: (a diffuse sensor: the shading changes with the slope's size only, and little).
LIGHTS: dict[str, Lights] = {
    "zones3": Lights("zones3", tuple(Light(az, c) for az, c in zip(
        LED_AZIMUTH_DEG, (_RED, _GREEN, _BLUE), strict=True))),
    "sides4": Lights("sides4", (Light(0.0, _RED, 1.15, 0.35), Light(90.0, _GREEN, 1.15, 0.35),
                                Light(180.0, _BLUE, 1.15, 0.35),
                                Light(270.0, (0.80, 0.85, 0.80), 1.15, 0.35))),
    "uniform": Lights("uniform", tuple(Light(a, (1.0, 1.0, 1.0), 1.3, 2.0)
                                       for a in range(0, 360, 45)), ambient_share=0.5),
}
DEFAULT_LIGHTS = "zones3"


def lights_named(lights: str | Lights) -> Lights:
    """The layout `lights` (a name of LIGHTS, or a Lights itself)."""
    if isinstance(lights, Lights):
        return lights
    if lights not in LIGHTS:
        raise ValueError(f"lights must be one of {', '.join(LIGHTS)}, got {lights!r}")
    return LIGHTS[lights]


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
    light: np.ndarray  # (K zones, 3 xyz, H, W) float32: unit vector from the pixel to the zone
    gain: np.ndarray  # (K zones, H, W) float32: vignetting * zone gain per unit of n.L
    ambient: np.ndarray  # (H, W, 3 channels) float32
    flat: np.ndarray  # (H, W, 3 channels) float32, noise-free image of the undeformed coating
    mix: np.ndarray  # (3 channels, K zones) float32: each channel's response to each zone
    lights: str = DEFAULT_LIGHTS  # the layout's name

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
        for k in range(self.light.shape[0]):
            lx, ly, lz = (self.light[k, i, rows, cols] for i in range(3))
            # n.L for the surface z = D(x, y) seen from the camera: n = (-p, -q, 1) / |.|.
            s = lz - p * lx
            s -= q * ly
            np.maximum(s, 0.0, out=s)
            s *= inv
            s *= self.gain[k, rows, cols]
            zones.append(s)
        if len(zones) <= 4:  # channels = mix @ zones
            out = cv2.transform(cv2.merge(zones), self.mix)
        else:
            out = np.ascontiguousarray(np.stack(zones, axis=-1) @ self.mix.T)
        out += self.ambient[rows, cols]
        return out


def _powers(mix: np.ndarray, lit0: np.ndarray, direct0: np.ndarray) -> np.ndarray | None:
    """Zone powers that make the centre read direct0 (three zones of independent colours), or
    None where they are not determined or not all positive."""
    if mix.shape != (3, 3):
        return None
    try:
        power = np.linalg.solve(mix * lit0[None, :], direct0)
    except np.linalg.LinAlgError:
        return None
    return power if bool(np.all(power > 0)) else None


def _fields(height: int, width: int, mm_per_px: float, vignetting: bool,
            nonuniform: bool, lights: Lights) -> Sensor:
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
    n_zones = len(lights.zones)
    light = np.empty((n_zones, 3, height, width), np.float32)
    gain = np.empty((n_zones, height, width))
    for k, zone in enumerate(lights.zones):
        a = math.radians(zone.azimuth_deg)
        # Zone position in pixel-frame mm (y down the rows, so the y-up azimuth flips sign).
        px, py, pz = (zone.radius * half_w * math.cos(a), -zone.radius * half_h * math.sin(a),
                      zone.height * half_diag)
        dx, dy, dz = px - x, py - y, np.full_like(x, pz)
        dist = np.sqrt(dx * dx + dy * dy + dz * dz)
        light[k, 0], light[k, 1], light[k, 2] = dx / dist, dy / dist, dz / dist
        d0 = math.sqrt(px * px + py * py + pz * pz)
        # Gain per unit of n.L, so that the flat coating (n.L = lz) receives (d0 / d)^falloff.
        gain[k] = (d0 / dist) ** zone.falloff * (pz / d0) / (dz / dist)
    # Scale the zones (or the channels) so that the flat coating at the centre reads FLAT_LEVEL.
    ic, jc = height // 2, width // 2
    direct0 = (1.0 - lights.ambient_share) * FLAT_LEVEL
    lit0 = gain[:, ic, jc] * light[:, 2, ic, jc]
    mix = lights.mix
    power = _powers(mix, lit0, direct0)
    if power is not None:
        gain *= power[:, None, None]
    else:  # zones of equal power, the camera's white balance
        mix = mix * (direct0 / (mix @ lit0))[:, None]
    if vignetting:
        r2 = ((xs - cx) ** 2 + (ys - cy) ** 2) * (mm_per_px / half_diag) ** 2
        vig = (1.0 + r2 / VIGNETTE_R**2) ** -2
    else:
        vig = np.ones((height, width))
    gain *= vig[None]
    ambient = (vig[..., None] * (lights.ambient_share * FLAT_LEVEL)[None, None, :]
               ).astype(np.float32)
    s = Sensor(height, width, mm_per_px, light, gain.astype(np.float32), ambient, ambient,
               mix.astype(np.float32), lights.name)
    flat = s.shade(np.zeros((height, width)), np.zeros((height, width)), slice(None), slice(None))
    return dataclasses.replace(s, flat=flat)


@lru_cache(maxsize=8)
def sensor(height: int, width: int, mm_per_px: float, vignetting: bool = True,
           nonuniform: bool = True, lights: str | Lights = DEFAULT_LIGHTS) -> Sensor:
    """The sensor fields for a frame size, scale and light layout (a name of LIGHTS or a
    Lights), computed once per process."""
    return _fields(height, width, mm_per_px, vignetting, nonuniform, lights_named(lights))


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
