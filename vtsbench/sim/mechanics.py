"""Generator 2 contact mechanics: partial slip, gel shear, rotation and uneven speed.

`Mechanics` holds the options (defaults from GelSight Mini video, docs/simulator.md "Generator
2: realistic slip"); the planner draws one `ContactPath` per sequence from them (speed profile,
rotation, shear capacity and preload), and the renderer turns the path and each frame's contact
into the gel surface's tangential displacement (`surface_displacement`).

The surface model is Cattaneo-Mindlin-like: with the gel's tangential displacement delta under
the contact rising towards its capacity delta_max (where gross slip starts), the stick region
is the part of the contact farther than (1 - c/a) of the deepest inner distance from the rim,
c/a = (1 - Q/muP)^(1/3) = sqrt(1 - delta/delta_max). Inside it the surface moves rigidly with
the object (translation and twist); over the slip annulus it lags, by rim_lag at the rim under
full sliding (Hertz traction on a half-space with Poisson's ratio 0.5); outside the contact the
shear decays as exp(-distance / shear_decay_mm).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Speed profiles of a window, in the order of `Mechanics.profile_mix`.
PROFILES: tuple[str, ...] = ("steady", "varying", "stick_slip", "jerk")
#: Region closing (mm): the gaps between touching texture peaks narrower than this are bridged.
CLOSE_MM = 0.3
#: Beyond this many decay lengths outside the contact the shear is set to exactly zero.
DECAY_CUT = 4.0


@dataclass(frozen=True)
class Mechanics:
    """Options of the contact mechanics and speed profiles of generator 2 (defaults: real)."""

    #: Shares of the speed profiles steady, varying, stick_slip, jerk.
    profile_mix: tuple[float, float, float, float] = (0.35, 0.55, 0.05, 0.05)
    #: Gamma shape of the frame steps of a varying profile: speed CV = 1 / sqrt(shape).
    speed_shape: float = 6.0
    #: Share of the steps of a stick-slip profile in which the object sticks (does not move).
    stick_step_share: float = 0.5
    #: Share of the window's motion that the jerk step (or the two jerk steps) carries.
    jerk_share: tuple[float, float] = (0.5, 0.9)
    #: Object rotation over a moving window (deg, log-uniform, either sense), about the contact.
    rotation_deg: tuple[float, float] = (0.2, 2.0)
    #: Gel surface displacement at which gross slip starts (mm, log-uniform).
    shear_capacity_mm: tuple[float, float] = (0.05, 0.3)
    #: Tangential load already on the contact at the window's first frame, share of capacity.
    preload: tuple[float, float] = (0.0, 0.9)
    #: Decay length (mm) of the gel shear outside the contact.
    shear_decay_mm: float = 5.0
    #: Lag of the surface at the contact rim under full sliding, share of the stick motion.
    rim_lag: float = 0.5
    #: Share of the press and slip windows in which contact is made or lost.
    contact_change_share: float = 0.15
    #: Height (mm) of the object's nominal top above the gel in frames without contact.
    lift_mm: tuple[float, float] = (0.08, 0.3)
    #: A held object loads the gel tangentially too (a grasp carries its weight): the gel of a
    #: held sequence is sheared by a preload share of its capacity, the same in every frame.
    held_shear: bool = True

    def __post_init__(self) -> None:
        """Refuse options outside their meaning (shares in [0, 1], positive lengths)."""
        if len(self.profile_mix) != len(PROFILES) or min(self.profile_mix) < 0 \
                or sum(self.profile_mix) <= 0:
            raise ValueError("profile_mix needs 4 non-negative shares, not all zero")
        for name in ("stick_step_share", "rim_lag", "contact_change_share"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} must be in [0, 1]")
        if self.speed_shape <= 0 or self.shear_decay_mm <= 0:
            raise ValueError("speed_shape and shear_decay_mm must be positive")


@dataclass(frozen=True)
class ContactPath:
    """What the gel does in each frame of one sequence (drawn by the planner).

    rotations_deg: the object's rotation from frame 0, counter-clockwise in the image (y up),
    about its contact centre; shear_px: the stick region's displacement from the unloaded gel
    (px, x right, y down); twist_deg: the rotation the stick region holds; stick: stick radius
    over contact radius (1: the whole contact sticks, 0: gross slip).
    """

    rotations_deg: tuple[float, ...]
    shear_px: tuple[tuple[float, float], ...]
    twist_deg: tuple[float, ...]
    stick: tuple[float, ...]
    profile: str = "steady"  # the speed profile (one of PROFILES), "held" for a held object
    contact_change: str | None = None  # 'made' or 'lost' inside the window, or None


def step_weights(mech: Mechanics, rng: np.random.Generator, n_steps: int,
                 kind: str | None = None) -> tuple[str, np.ndarray]:
    """A speed profile: its kind and the share of the motion in each of n_steps frame steps."""
    if kind is None:
        p = np.asarray(mech.profile_mix, float)
        kind = PROFILES[int(rng.choice(len(PROFILES), p=p / p.sum()))]
    if n_steps <= 1:
        return kind, np.ones(max(n_steps, 0))
    if kind == "steady":
        w = np.ones(n_steps)
    elif kind == "varying":
        w = rng.gamma(mech.speed_shape, size=n_steps)
    elif kind == "stick_slip":
        w = rng.gamma(mech.speed_shape, size=n_steps)
        stuck = rng.random(n_steps) < mech.stick_step_share
        stuck[int(rng.integers(n_steps))] = False  # at least one step moves
        w[stuck] = 0.0
    elif kind == "jerk":
        n_jerk = 1 if n_steps < 4 else int(rng.integers(1, 3))
        at = rng.choice(n_steps, size=n_jerk, replace=False)
        rest = rng.gamma(mech.speed_shape, size=n_steps)
        rest[at] = 0.0
        share = float(rng.uniform(*mech.jerk_share))
        w = rest * ((1.0 - share) / rest.sum()) if rest.sum() > 0 else rest
        u = 1.0 if n_jerk == 1 else float(rng.uniform(0.6, 0.9))
        w[at] = share * np.asarray([u, 1.0 - u][:n_jerk])
    else:
        raise ValueError(f"unknown speed profile {kind!r}")
    return kind, w / w.sum()


def progress(weights: np.ndarray) -> tuple[float, ...]:
    """Share of the motion reached at each frame: 0 at the first, exactly 1 at the last."""
    c = np.concatenate([[0.0], np.cumsum(weights)])
    c /= c[-1] if c[-1] > 0 else 1.0
    c[-1] = 1.0
    return tuple(float(v) for v in c)


def _log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    """A log-uniform draw in [lo, hi]; 0 when hi is 0 (the effect off; the draw is still
    taken, so that the other draws of the sequence stay the same)."""
    u = float(rng.random())
    if hi <= 0.0:
        return 0.0
    return float(math.exp(math.log(lo) + u * (math.log(hi) - math.log(lo))))


def contact_path(mech: Mechanics, rng: np.random.Generator, prog: tuple[float, ...],
                 total_px: tuple[float, float], mm_per_px: float, first_contact: int = 0,
                 profile: str = "steady", contact_change: str | None = None) -> ContactPath:
    """Draw rotation, capacity and preload; the stick displacement, twist and stick ratio per
    frame of an object that moves total_px (x right, y down) along prog.

    The gel takes the object's motion from the first frame in contact until its displacement
    reaches the capacity (stick region shrinking as sqrt(1 - delta / capacity)); beyond it the
    object slides and the surface stays at capacity. Contact made inside the window starts
    unloaded.
    """
    n = len(prog)
    sign = 1.0 if rng.random() < 0.5 else -1.0
    theta = sign * _log_uniform(rng, *mech.rotation_deg)
    cap = _log_uniform(rng, *mech.shear_capacity_mm) / mm_per_px
    pre = float(rng.uniform(*mech.preload))
    dist = math.hypot(*total_px)
    if first_contact > 0 or dist == 0.0:  # touch-down, or no tangential load
        pre = 0.0
    ex, ey = (total_px[0] / dist, total_px[1] / dist) if dist > 0 else (0.0, 0.0)
    p0 = prog[min(first_contact, n - 1)]
    rotations, shear, twist, stick = [], [], [], []
    for t in range(n):
        rotations.append(theta * prog[t])
        moved = max(0.0, prog[t] - p0) * dist if t >= first_contact else 0.0
        delta = min(pre * cap + moved, cap) if t >= first_contact else 0.0
        held = 1.0 if moved <= 0 else (delta - pre * cap) / moved
        shear.append((delta * ex, delta * ey))
        twist.append(theta * max(0.0, prog[t] - p0) * (held if dist > 0 else 1.0))
        stick.append(math.sqrt(max(0.0, 1.0 - delta / cap)))
    return ContactPath(tuple(rotations), tuple(shear), tuple(twist), tuple(stick), profile,
                       contact_change)


def held_path(mech: Mechanics, rng: np.random.Generator, n: int,
              mm_per_px: float) -> ContactPath:
    """The path of a held object: no motion, the gel sheared by a preload share of its
    capacity in a random direction in every frame (none with `held_shear` off)."""
    cap = _log_uniform(rng, *mech.shear_capacity_mm) / mm_per_px
    pre = float(rng.uniform(*mech.preload))
    angle = float(rng.uniform(0.0, 2.0 * math.pi))
    delta = pre * cap if mech.held_shear else 0.0
    shear = (delta * math.cos(angle), delta * math.sin(angle))
    stick = math.sqrt(max(0.0, 1.0 - delta / cap))
    return ContactPath((0.0,) * n, (shear,) * n, (0.0,) * n, (stick,) * n, "held")


def _region(contact: np.ndarray, f: int, close_px: int) -> np.ndarray:
    """Contact on the grid reduced by f (a cell touches if any pixel does), gaps closed."""
    import cv2

    h, w = contact.shape
    hc, wc = -(-h // f), -(-w // f)
    cells = np.zeros((hc, wc), np.uint8)
    bx, by, bw, bh = cv2.boundingRect(contact.view(np.uint8))
    if bw == 0 or bh == 0:
        return cells
    # only the contact's box, in whole cells
    y0, y1 = by // f, (by + bh - 1) // f + 1
    x0, x1 = bx // f, (bx + bw - 1) // f + 1
    box = np.zeros(((y1 - y0) * f, (x1 - x0) * f), bool)
    sub = contact[y0 * f:y1 * f, x0 * f:x1 * f]
    box[:sub.shape[0], :sub.shape[1]] = sub
    cells[y0:y1, x0:x1] = box.reshape(y1 - y0, f, x1 - x0, f).any(axis=(1, 3))
    if close_px > 0:
        k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * close_px + 1, 2 * close_px + 1))
        cells = cv2.morphologyEx(cells, cv2.MORPH_CLOSE, k)
    return cells


def surface_field(cells: np.ndarray, cell_mm: float, centre: tuple[float, float],
                  shear: tuple[float, float], twist_deg: float, stick: float,
                  mech: Mechanics, cell_px: float = 1.0) -> np.ndarray:
    """Tangential displacement (h, w, 2) of the gel surface from the unloaded gel, in px, on a
    grid of cells (each cell_mm wide, cell_px px) holding the contact region `cells`.

    centre is the contact centre (px of the full frame) about which the stick region twists.
    """
    import cv2

    h, w = cells.shape
    out = np.zeros((h, w, 2), np.float32)
    if not cells.any() or (shear == (0.0, 0.0) and twist_deg == 0.0):
        return out
    inside = cv2.distanceTransform(cells, cv2.DIST_L2, 5)
    outside = cv2.distanceTransform(1 - cells, cv2.DIST_L2, 5) * np.float32(cell_mm)
    xi = 1.0 - inside / inside.max()  # 0 at the deepest inner point, ~1 at the rim
    c = min(max(stick, 0.0), 1.0)
    lag = mech.rim_lag * (1.0 - c * c)
    g = np.ones((h, w), np.float32)
    if c < 1.0:
        ann = xi > c
        g[ann] = 1.0 - lag * ((xi[ann] - c) / (1.0 - c)) ** 2
    off = cells == 0
    decay = np.exp(-outside[off] / np.float32(mech.shear_decay_mm))
    decay[outside[off] > DECAY_CUT * mech.shear_decay_mm] = 0.0
    g[off] = (1.0 - lag) * decay
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    dx = (xs + 0.5) * np.float32(cell_px) - 0.5 - np.float32(centre[0])
    dy = (ys + 0.5) * np.float32(cell_px) - 0.5 - np.float32(centre[1])
    a = math.radians(twist_deg)
    cm, sn = np.float32(math.cos(a) - 1.0), np.float32(math.sin(a))
    # counter-clockwise on screen (y down): (dx, dy) -> (cos dx + sin dy, -sin dx + cos dy)
    out[..., 0] = g * (np.float32(shear[0]) + cm * dx + sn * dy)
    out[..., 1] = g * (np.float32(shear[1]) - sn * dx + cm * dy)
    return out


def cell_factor(mm_per_px: float) -> int:
    """Reduction of the grid on which the surface field is solved (about 0.1 mm cells)."""
    return max(1, round(0.1 / mm_per_px))


def _same_frame(contact: np.ndarray, motion_px: np.ndarray, path: ContactPath, t: int) -> bool:
    """Whether frame t's surface field is frame t-1's (same load, pose and contact)."""
    return (path.shear_px[t] == path.shear_px[t - 1] and path.twist_deg[t] == path.twist_deg[t - 1]
            and path.stick[t] == path.stick[t - 1]
            and bool((motion_px[t] == motion_px[t - 1]).all())
            and np.array_equal(contact[t], contact[t - 1]))


def surface_displacement(contact: np.ndarray, motion_px: np.ndarray, pivot: tuple[float, float],
                         path: ContactPath, mech: Mechanics, mm_per_px: float,
                         from_rest: bool = False) -> np.ndarray:
    """Gel surface displacement (T, H, W, 2) float32 px from frame 0 (from_rest: from the
    unloaded gel, so that a preloaded first frame is already displaced), from each frame's
    contact.

    Solved on a grid of about 0.1 mm cells over the frame and interpolated bilinearly; the
    contact centre of frame t is the pivot moved by the object's displacement motion_px[t].
    """
    import cv2

    t_n, h, w = contact.shape
    f = cell_factor(mm_per_px)
    close = max(1, round(CLOSE_MM / (2.0 * f * mm_per_px)))
    fields: list[np.ndarray] = []
    for t in range(t_n):
        if t and _same_frame(contact, motion_px, path, t):  # nothing changed: same field
            fields.append(fields[-1])
            continue
        cells = _region(contact[t], f, close)
        centre = (pivot[0] + float(motion_px[t, 0]), pivot[1] + float(motion_px[t, 1]))
        fields.append(surface_field(cells, f * mm_per_px, centre, path.shear_px[t],
                                    path.twist_deg[t], path.stick[t], mech, float(f)))
    out = np.zeros((t_n, h, w, 2), np.float32)
    for t in range(0 if from_rest else 1, t_n):
        if t and fields[t] is fields[t - 1]:
            out[t] = out[t - 1]
            continue
        d = fields[t] if from_rest else fields[t] - fields[0]
        if not d.any():
            continue
        if f > 1:
            d = cv2.resize(d, (d.shape[1] * f, d.shape[0] * f), interpolation=cv2.INTER_LINEAR)
        out[t] = d[:h, :w]
    return out
