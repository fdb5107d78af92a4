"""The 15 object classes as height fields (mm) with their micro-texture, plus the calibration ball.

A shape is a function of object-frame coordinates (u, v) in mm whose maximum is 0 (the nominal
top, the part that meets the gel first) and which is -BIG where the object has no surface. The
micro-texture is a separate, bounded function added on top, so that a scene that needs no
texture (a calibration press) never evaluates it. Random variants (texture phases, tooth
counts, key cuts) come from a per-instance vector of uniform numbers.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

#: Height (mm) standing for "no surface here": far below any press depth.
BIG = 1.0e3
#: Length of the per-instance random vector.
N_PARAMS = 48

Field = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class ObjectClass:
    """One object class: its height field, micro-texture and documentation."""

    name: str
    group: str
    geometry: str
    texture_doc: str
    radius_mm: float  # footprint radius around the object origin
    depth_mm: tuple[float, float]  # press depth range
    shape: Field = lambda u, v, t: np.zeros_like(u)
    texture: Field | None = None
    texture_amp_mm: float = 0.0  # bound on |texture|


@dataclass(frozen=True, eq=False)
class ObjectInstance:
    """An object class with a pose (rotation, scale) and its random variant parameters."""

    cls: ObjectClass
    rotation_deg: float = 0.0
    scale: float = 1.0
    params: np.ndarray = field(default_factory=lambda: np.full(N_PARAMS, 0.5))

    @property
    def radius_mm(self) -> float:
        """Footprint radius of this instance (mm)."""
        return self.cls.radius_mm * self.scale

    @property
    def texture_bound_mm(self) -> float:
        """Bound on |texture| of this instance (mm); 0 without texture."""
        return self.cls.texture_amp_mm * self.scale if self.cls.texture is not None else 0.0

    def local(self, x_mm: np.ndarray, y_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Object-frame (u, v) of pixel-frame offsets (x right, y down), divided by the scale."""
        a = math.radians(self.rotation_deg)
        c, s = math.cos(a) / self.scale, math.sin(a) / self.scale
        return c * x_mm + s * y_mm, c * y_mm - s * x_mm

    def shape(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Height (mm, float64, max 0) of the untextured object at object-frame (u, v)."""
        return self.cls.shape(u, v, self.params) * self.scale

    def texture(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Micro-texture height (mm, float32) at object-frame (u, v)."""
        if self.cls.texture is None:
            return np.zeros(np.broadcast_shapes(u.shape, v.shape), np.float32)
        t = self.cls.texture(u.astype(np.float32), v.astype(np.float32), self.params)
        return t * np.float32(self.scale)


# -- helpers ---------------------------------------------------------------------------------

def _waves(u: np.ndarray, v: np.ndarray, t: np.ndarray, n: int, lam: tuple[float, float],
           amp: float, angle_deg: float | None = None, spread_deg: float = 180.0,
           offset: int = 0) -> np.ndarray:
    """Band-limited roughness: n plane waves of random direction, wavelength and phase.

    The sum is bounded by amp. angle_deg (with +-spread_deg) restricts the wave directions, which
    gives directional marks (brushing, scratches).
    """
    out = np.zeros(np.broadcast_shapes(u.shape, v.shape), np.float32)
    for i in range(n):
        a, b, c = (float(x) for x in t[(offset + 3 * i + np.arange(3)) % N_PARAMS])
        ang = math.radians((angle_deg or 0.0) + (2 * a - 1) * spread_deg)
        k = 2 * math.pi / (lam[0] * (lam[1] / lam[0]) ** b)
        out += np.cos(np.float32(k * math.cos(ang)) * u + np.float32(k * math.sin(ang)) * v
                      + np.float32(2 * math.pi * c))
    out *= np.float32(amp / n)
    return out


def _rings(u: np.ndarray, v: np.ndarray, t: np.ndarray, lam: float, amp: float) -> np.ndarray:
    """Concentric turning marks of wavelength lam (mm)."""
    r = np.sqrt(u * u + v * v)
    return np.cos(r * np.float32(2 * math.pi / lam) + np.float32(2 * math.pi * t[0])) * \
        np.float32(amp)


def _cap(r2: np.ndarray, radius: float, footprint: float) -> np.ndarray:
    """Spherical cap of a radius, top at 0, cut at a footprint radius."""
    h = np.sqrt(np.maximum(radius * radius - r2, 0.0)) - radius
    return np.where(r2 < footprint * footprint, h, -BIG)


def _rounded_box(u: np.ndarray, v: np.ndarray, hu: float, hv: float, rho: float) -> np.ndarray:
    """Flat-topped box of half sizes (hu, hv) whose top edges are rounded with radius rho."""
    du = np.maximum(np.abs(u) - (hu - rho), 0.0)
    dv = np.maximum(np.abs(v) - (hv - rho), 0.0)
    e2 = du * du + dv * dv
    return np.where(e2 < rho * rho, np.sqrt(np.maximum(rho * rho - e2, 0.0)) - rho, -BIG)


# -- geometric indenters ---------------------------------------------------------------------

def _sphere(u, v, t):
    """Spherical cap of radius 4 mm."""
    return _cap(u * u + v * v, 4.0, 4.0)


def _sphere_tex(u, v, t):
    """Isotropic bead-blast roughness."""
    return _waves(u, v, t, 6, (0.12, 0.35), 0.004)


def _cylinder(u, v, t):
    """A lying rod (capsule) of radius 1.5 mm and length 9 mm along u."""
    e = np.maximum(np.abs(u) - 3.0, 0.0)
    return _cap(e * e + v * v, 1.5, 1.5)


def _cylinder_tex(u, v, t):
    """Circumferential lathe marks across the rod, plus faint roughness."""
    lam = 0.18 + 0.1 * float(t[1])
    return np.cos(u * np.float32(2 * math.pi / lam) + np.float32(2 * math.pi * t[0])) * \
        np.float32(0.003) + _waves(u, v, t, 3, (0.1, 0.3), 0.001, offset=6)


def _cone(u, v, t):
    """Cone of slope 0.7 with a hyperbolically rounded tip."""
    r = np.sqrt(u * u + v * v)
    return np.where(r < 4.0, -0.7 * (np.sqrt(r * r + 0.16) - 0.4), -BIG)


def _cone_tex(u, v, t):
    """Concentric machining rings."""
    return _rings(u, v, t, 0.2, 0.003)


def _cube(u, v, t):
    """Flat 5 x 5 mm face with rounded edges."""
    return _rounded_box(u, v, 2.5, 2.5, 0.4)


def _cube_tex(u, v, t):
    """Straight milling marks plus faint roughness."""
    lam = 0.22 + 0.1 * float(t[1])
    return np.cos(v * np.float32(2 * math.pi / lam) + np.float32(2 * math.pi * t[0])) * \
        np.float32(0.0025) + _waves(u, v, t, 3, (0.1, 0.3), 0.0015, offset=6)


def _ridge(u, v, t):
    """Triangular prism along u with a rounded crest."""
    h = -0.9 * (np.sqrt(v * v + 0.0225) - 0.15)
    return np.where((np.abs(u) < 4.5) & (np.abs(v) < 2.0), h, -BIG)


def _ridge_tex(u, v, t):
    """Scratches along the ridge: waves whose crests run along u."""
    return _waves(u, v, t, 5, (0.08, 0.4), 0.004, angle_deg=90.0, spread_deg=4.0)


# -- hardware tools --------------------------------------------------------------------------

def _hex_nut(u, v, t):
    """Hexagonal nut face: bore, bore chamfer and conical corner chamfer."""
    r = np.sqrt(u * u + v * v)
    hd = np.maximum(np.abs(u), np.maximum(np.abs(0.5 * u + 0.8660254 * v),
                                          np.abs(0.5 * u - 0.8660254 * v)))
    h = -0.6 * np.maximum(r - 3.3, 0.0) - np.maximum(2.05 - r, 0.0)
    return np.where((hd <= 3.5) & (r >= 1.75), h, -BIG)


def _hex_nut_tex(u, v, t):
    """Turning rings plus faint roughness."""
    return _rings(u, v, t, 0.15, 0.0025) + _waves(u, v, t, 3, (0.1, 0.3), 0.001, offset=3)


def _screw(u, v, t):
    """Threaded rod along u: major radius 2 mm, pitch 0.8 mm, depth 0.35 mm, lead angle."""
    w = (u - 0.06 * v) / 0.8
    tri = np.abs(2.0 * (w - np.floor(w)) - 1.0)
    radius = 1.65 + 0.35 * np.clip((tri - 0.1) / 0.8, 0.0, 1.0)
    h = np.sqrt(np.maximum(radius * radius - v * v, 0.0)) - 2.0
    return np.where((np.abs(u) < 4.5) & (np.abs(v) < radius), h, -BIG)


def _screw_tex(u, v, t):
    """Fine isotropic roughness."""
    return _waves(u, v, t, 4, (0.08, 0.25), 0.0015)


def _gear(u, v, t):
    """Spur gear face: trapezoid-ish teeth, bevelled rim, recessed web, bore."""
    r = np.sqrt(u * u + v * v)
    teeth = 12 + int(t[40] * 7)
    tooth = np.clip(1.8 * (0.5 + 0.5 * np.cos(teeth * np.arctan2(v, u) + 6.2832 * t[41])) - 0.4,
                    0.0, 1.0)
    rim = 3.3 + 0.7 * tooth
    h = -1.2 * np.maximum(r - rim + 0.15, 0.0)
    h -= 0.25 * np.clip((r - 1.6) / 0.1, 0.0, 1.0) * np.clip((2.6 - r) / 0.1, 0.0, 1.0)
    return np.where((r < rim) & (r > 1.0), h, -BIG)


def _gear_tex(u, v, t):
    """Turning rings plus faint roughness."""
    return _rings(u, v, t, 0.12, 0.002) + _waves(u, v, t, 3, (0.1, 0.3), 0.001, offset=3)


def _key(u, v, t):
    """Blade along -u with five V cuts on the +v edge, a keyway groove, a bow with a hole."""
    cut = np.zeros_like(u)
    for k in range(5):
        depth = 0.15 + 0.45 * float(t[42 + k])
        cut = np.maximum(cut, depth - np.abs(u - (-3.7 + 0.9 * k)))
    tip = np.clip((u + 4.5) / 0.8, 0.0, 1.0)
    blade = (u > -4.5) & (u < 2.2) & (v > -1.3 * tip) & (v < 1.3 * tip - cut)
    bow = ((u - 3.8) ** 2 + v * v < 2.3**2) & ((u - 4.6) ** 2 + v * v > 0.6**2)
    h = np.where(u < 2.0, -0.15 * np.exp(-((v + 0.3) / 0.2) ** 2), 0.0)
    return np.where(blade | bow, h, -BIG)


def _key_tex(u, v, t):
    """Brushed lines along the blade."""
    return _waves(u, v, t, 5, (0.06, 0.3), 0.002, angle_deg=90.0, spread_deg=3.0)


# -- electronic connectors -------------------------------------------------------------------

def _usb_plug(u, v, t):
    """USB-A plug face: a 12 x 4.5 mm shell with a rounded 0.3 mm wall and a recessed tongue."""
    d_out = np.maximum(np.abs(u) - 6.0, np.abs(v) - 2.25)
    c = d_out + 0.15
    rim = np.sqrt(np.maximum(0.0225 - c * c, 0.0)) - 0.15
    au = np.abs(u)
    tongue = (au < 5.0) & (v > -1.95) & (v < -0.05)
    pads = tongue & (v < -0.5) & ((np.abs(au - 1.0) < 0.5) | (np.abs(au - 3.0) < 0.5))
    h = np.where(pads, -0.26, np.where(tongue, -0.2, -BIG))
    return np.where((d_out < 0.0) & (d_out > -0.3), rim, h)


def _usb_tex(u, v, t):
    """Stamped-metal grain."""
    return _waves(u, v, t, 5, (0.08, 0.3), 0.002)


_PIN_U = (-3.81, -1.27, 1.27, 3.81)
_PIN_V = (-1.27, 1.27)


def _pin_header(u, v, t):
    """2 x 4 square pins (0.64 mm, pitch 2.54 mm) with pyramidal tips; tiny height differences."""
    iu = np.clip(np.round((u + 3.81) / 2.54), 0, 3)
    iv = np.clip(np.round((v + 1.27) / 2.54), 0, 1)
    a = u - (-3.81 + 2.54 * iu)
    b = v - (-1.27 + 2.54 * iv)
    m = np.maximum(np.abs(a), np.abs(b))
    offsets = 0.03 * (np.asarray(t[32:40]) - 0.5)
    offsets = offsets - offsets.max()
    h = -2.0 * np.maximum(m - 0.18, 0.0) + offsets[(iu + 4 * iv).astype(np.intp)]
    return np.where(m < 0.32, h, -BIG)


def _pin_tex(u, v, t):
    """Plating roughness."""
    return _waves(u, v, t, 3, (0.08, 0.2), 0.0015)


def _dip_chip(u, v, t):
    """DIP-8 body 9.6 x 6.4 mm: rounded edges, a notch at one end, the pin-1 dimple."""
    h = _rounded_box(u, v, 4.8, 3.2, 0.35)
    notch = (u + 4.8) ** 2 + v * v < 0.49
    h = np.where(notch, np.minimum(h, -0.35), h)
    rho2 = (u + 3.6) ** 2 + (v - 2.0) ** 2
    return h - 0.08 * np.maximum(1.0 - rho2 / 0.25, 0.0)


def _dip_tex(u, v, t):
    """Matte moulding finish."""
    return _waves(u, v, t, 6, (0.08, 0.2), 0.004)


# -- organic textures ------------------------------------------------------------------------

def _fabric(u, v, t):
    """The dome the cloth lies on."""
    return _cap(u * u + v * v, 12.0, 6.0)


def _fabric_tex(u, v, t):
    """Plain weave: warp threads along u and weft threads along v, crossing over and under."""
    p = np.float32(0.45 + 0.25 * float(t[40]))
    a, ht, w = np.float32(0.02), np.float32(0.025), np.float32(0.45)
    pu, pv = u / p, v / p
    und = np.cos(np.float32(math.pi) * pu) * np.cos(np.float32(math.pi) * pv) * a
    dv = np.abs(pv - np.round(pv)) / w
    du = np.abs(pu - np.round(pu)) / w
    warp = np.where(dv < 1, und + ht * np.sqrt(np.maximum(1 - dv * dv, 0)), -a - ht)
    weft = np.where(du < 1, ht * np.sqrt(np.maximum(1 - du * du, 0)) - und, -a - ht)
    return np.maximum(np.maximum(warp, weft), -a - np.float32(0.5) * ht)


def _leaf(u, v, t):
    """A leaf (pointed ellipse, raised midrib) lying on a dome; outside it the bare dome."""
    dome = _cap(u * u + v * v, 14.0, 6.0)
    q = np.clip(1.0 - (u / 5.5) ** 2, 0.0, 1.0)
    inside = np.abs(v) < 2.6 * q**0.8
    rib = 0.05 * np.maximum(1.0 - (v / 0.25) ** 2, 0.0)
    return np.where(inside, dome + rib - 0.05, dome - 0.25)


def _leaf_tex(u, v, t):
    """Lateral veins at about 50 degrees off the midrib, plus a fine cellular bumpiness."""
    w = (u - np.abs(v) * np.float32(0.85)) / np.float32(1.1) + float(t[40])
    dist = np.abs(w - np.round(w)) * np.float32(1.1 / 0.08)
    veins = np.maximum(1 - dist * dist, 0) * np.float32(0.025)
    return veins + _waves(u, v, t, 6, (0.07, 0.15), 0.004)


def _wood(u, v, t):
    """The wood block's dome."""
    return _cap(u * u + v * v, 15.0, 6.0)


def _wood_tex(u, v, t):
    """Growth rings (sharp latewood ridges) on a wavy grain, pores along it, fibre lines."""
    two_pi = np.float32(2 * math.pi)
    w = v + np.float32(0.4) * np.sin(u * np.float32(2 * math.pi / 5.0) + float(two_pi * t[40])) \
        + np.float32(0.12) * np.sin(u * np.float32(2 * math.pi / 1.7) + float(two_pi * t[41]))
    ring = (np.float32(0.5) - np.float32(0.5) * np.cos(w * np.float32(2 * math.pi / 0.55))) ** 3
    pores = np.cos(u * np.float32(2 * math.pi / 0.35)) * np.cos(w * np.float32(2 * math.pi / 0.18))
    pits = np.maximum(pores - np.float32(0.85), 0) * np.float32(0.015 / 0.15)
    return ring * np.float32(0.03) - pits + \
        _waves(u, v, t, 4, (0.06, 0.2), 0.003, angle_deg=90.0, spread_deg=5.0)


# -- catalogue -------------------------------------------------------------------------------

_DEEP = (0.2, 1.2)
_FLAT = (0.1, 0.7)
_DOME = (0.15, 0.8)

SPHERE = ObjectClass("sphere", "geometric", "spherical cap, radius 4 mm",
                     "bead-blast roughness, 4 um", 4.0, _DEEP, _sphere, _sphere_tex, 0.004)
CYLINDER = ObjectClass("cylinder", "geometric",
                       "lying rod (capsule), radius 1.5 mm, length 9 mm",
                       "circumferential lathe marks 0.18-0.28 mm, 3 um", 4.5, (0.2, 1.0),
                       _cylinder, _cylinder_tex, 0.004)
CONE = ObjectClass("cone", "geometric", "cone, slope 0.7 (35 deg), tip radius 0.4 mm",
                   "concentric machining rings 0.2 mm, 3 um", 4.0, _DEEP, _cone, _cone_tex,
                   0.003)
CUBE = ObjectClass("cube", "geometric", "5 x 5 mm flat face, edges rounded 0.4 mm",
                   "straight milling marks 0.22-0.32 mm, 2.5 um", 3.6, _FLAT, _cube, _cube_tex,
                   0.004)
RIDGE = ObjectClass("ridge", "geometric",
                    "triangular prism 9 x 4 mm, slope 0.9, crest radius 0.15 mm",
                    "longitudinal scratches, 4 um", 5.0, _DEEP, _ridge, _ridge_tex, 0.004)
HEX_NUT = ObjectClass("hex_nut", "hardware", "hexagon 7 mm across flats, 3.5 mm bore, "
                      "30 deg corner chamfer", "turning rings 0.15 mm, 2.5 um", 4.1, _FLAT,
                      _hex_nut, _hex_nut_tex, 0.0035)
SCREW_THREAD = ObjectClass("screw_thread", "hardware", "lying M4 thread: pitch 0.8 mm, "
                           "depth 0.35 mm, length 9 mm", "fine roughness, 1.5 um", 5.0, (0.2, 1.0),
                           _screw, _screw_tex, 0.0015)
GEAR = ObjectClass("gear", "hardware", "spur gear face, 12-18 teeth, tip radius 4 mm, "
                   "recessed web, 2 mm bore", "turning rings 0.12 mm, 2 um", 4.05, _FLAT,
                   _gear, _gear_tex, 0.003)
KEY = ObjectClass("key", "hardware", "flat key: blade with five random V cuts and a keyway "
                  "groove, bow with a hole", "brushed lines along the blade, 2 um", 6.2, _FLAT,
                  _key, _key_tex, 0.002)
USB_PLUG = ObjectClass("usb_plug", "connector", "USB-A plug face: 12 x 4.5 mm shell, 0.3 mm "
                       "rounded wall, tongue recessed 0.2 mm with four contact pads",
                       "stamped-metal grain, 2 um", 6.45, (0.1, 0.5), _usb_plug, _usb_tex, 0.002)
PIN_HEADER = ObjectClass("pin_header", "connector", "2 x 4 square pins 0.64 mm at 2.54 mm "
                         "pitch, pyramidal tips, heights within 30 um", "plating roughness, "
                         "1.5 um", 4.5, (0.1, 0.6), _pin_header, _pin_tex, 0.0015)
DIP_CHIP = ObjectClass("dip_chip", "connector", "DIP-8 body 9.6 x 6.4 mm, edges rounded "
                       "0.35 mm, end notch, pin-1 dimple", "matte moulding finish, 4 um", 5.8,
                       _FLAT, _dip_chip, _dip_tex, 0.004)
FABRIC = ObjectClass("fabric", "organic", "cloth over a dome of radius 12 mm",
                     "plain weave, period 0.45-0.7 mm, 45 um relief", 6.0, _DOME, _fabric,
                     _fabric_tex, 0.046)
LEAF = ObjectClass("leaf", "organic", "leaf 11 x 5 mm with a raised midrib on a dome of "
                   "radius 14 mm", "lateral veins 25 um, cell bumps 4 um", 6.0, _DOME, _leaf,
                   _leaf_tex, 0.03)
WOOD = ObjectClass("wood", "organic", "wood block rounded to a dome of radius 15 mm",
                   "growth rings 0.55 mm (30 um ridges), pores, fibre lines", 6.0, _DOME, _wood,
                   _wood_tex, 0.034)

#: The 15 classes in the fixed order used by n_objects (groups interleaved, so any K >= 4
#: spans all four groups).
OBJECTS: tuple[ObjectClass, ...] = (
    SPHERE, HEX_NUT, USB_PLUG, FABRIC,
    CYLINDER, SCREW_THREAD, PIN_HEADER, LEAF,
    CONE, GEAR, DIP_CHIP, WOOD,
    CUBE, KEY, RIDGE,
)
GROUPS: tuple[str, ...] = ("geometric", "hardware", "connector", "organic")

BALL_RADIUS_MM = 3.0


def _ball(u, v, t):
    """The calibration ball: a smooth sphere of radius BALL_RADIUS_MM."""
    return _cap(u * u + v * v, BALL_RADIUS_MM, BALL_RADIUS_MM)


#: The calibration ball: a smooth 3 mm-radius sphere (no texture).
BALL = ObjectClass("calibration_ball", "calibration", "sphere, radius 3 mm", "none",
                   BALL_RADIUS_MM, (0.1, 1.2), _ball, None, 0.0)


def by_name(name: str) -> ObjectClass:
    """The object class (or the calibration ball) of a name."""
    for c in (*OBJECTS, BALL):
        if c.name == name:
            return c
    raise KeyError(name)


def random_instance(cls: ObjectClass, rng: np.random.Generator) -> ObjectInstance:
    """An instance with a uniform rotation, a scale in [0.85, 1.15] and random variants."""
    if cls is BALL:
        return ObjectInstance(cls, 0.0, 1.0, rng.random(N_PARAMS))
    rotation = float(rng.uniform(0.0, 360.0))
    scale = float(rng.uniform(0.85, 1.15))
    return ObjectInstance(cls, rotation, scale, rng.random(N_PARAMS))
