"""Motion and appearance statistics of one window of frames, to compare a sensor with another
(a real one with the simulator) on the same definitions.

Frames are turned to grey, G = 0.299 R + 0.587 G + 0.114 B in DN (float, not rounded).

- **Reference**: a no-contact frame given by the caller (the session's background, else a
  frame of the source before contact; see `vtsbench.stats.folder`).
- **Contact** of a frame: pixels where the frame and the reference, both Gaussian-blurred by
  CONTACT_BLUR_PX, differ by more than CONTACT_DN in grey. Contact is *present* in a frame
  when it covers at least MIN_CONTACT_SHARE of the frame.
- **Region**: the contact of the first frame when present there, else the union of the
  contacts of all frames (contact made inside the window), eroded by EDGE_PX (where the flow
  is pulled towards the still surround; the region itself when erosion leaves less than
  MIN_REGION_SHARE of the frame). Motion statistics use its pixels.
- **Displacement field**: OpenCV's DIS optical flow (medium preset) from the first frame to
  each later frame, on the grey frames rounded to uint8; u_t(p) in px, x right, y down.
- **Median motion** m_t: the component-wise median of u_t over the region (m_0 = 0). The
  window is **moving** when |m_last| > MOVING_PX; motion statistics are defined on moving
  windows only.
- **Translation R²**: 1 - sum |u - mean u|² / sum |u|² over the region, u the first-to-last
  field: the share of the displacement's energy one translation explains (1 = a rigid shift).
- **Co-moving share**: share of the region whose first-to-last displacement lies within
  max(COMOVE_REL |m|, COMOVE_PX) of m.
- **Rotation** and **strain**: a least-squares affine fit u = t + A (p - centroid) over the
  region; F = I + A is split by polar decomposition F = R U. Rotation is |angle of R| in
  degrees; strain relative to translation is max |eigenvalue of U - I| times the region's
  radius sqrt(area / pi), divided by |m|: how far the deformation moves the region's edge
  against how far the region moves.
- **Largest-step share** and **speed CV**: with steps s_t = |m_t - m_(t-1)| (t = 1..T-1),
  max s / sum s (1/(T-1) for steady motion, 1 for one jerk) and std(s) / mean(s) (population
  standard deviation; 0 for steady motion).
- **Phase-correlation miss**: on moving windows with |m| > PHASE_MIN_PX, whether
  cv2.phaseCorrelate of the whole first and last grey frames (Hanning window) returns a shift
  shorter than PHASE_MISS_PX: a whole-frame registration that sees no motion.
- **Contact made or lost**: contact is present in some frames of the window and not in others.
- **Imprint texture**: in the frame with the largest contact, the RMS over its contact of the
  high-pass G - GaussianBlur(G, HIGHPASS_PX).
- **Off-contact texture**: the same high-pass RMS in that frame over the pixels off contact:
  outside the union of the window's contacts dilated by OFF_MARGIN_PX (the whole frame when
  there is no contact). A fixed pattern (markers, border, dust) shows here as well as noise.
- **Temporal noise**: sqrt of the mean, over the off-contact pixels, of each pixel's variance
  over the window's frames (ddof 1): fresh noise per frame shows here, a fixed pattern does not.

Off-contact statistics need OFF_MIN_SHARE of the frame off contact; texture on contact needs
contact present.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

CONTACT_BLUR_PX = 2.0
CONTACT_DN = 3.0
MIN_CONTACT_SHARE = 0.005
EDGE_PX = 8
MIN_REGION_SHARE = 0.001
MOVING_PX = 0.5
COMOVE_REL = 0.3
COMOVE_PX = 0.5
PHASE_MIN_PX = 1.0
PHASE_MISS_PX = 0.5
HIGHPASS_PX = 2.0
OFF_MARGIN_PX = 5
OFF_MIN_SHARE = 0.01

#: The definitions' constants, written with every result so that numbers stay comparable.
SETTINGS = {"contact_blur_px": CONTACT_BLUR_PX, "contact_dn": CONTACT_DN,
            "min_contact_share": MIN_CONTACT_SHARE, "edge_px": EDGE_PX,
            "min_region_share": MIN_REGION_SHARE, "moving_px": MOVING_PX,
            "comove_rel": COMOVE_REL, "comove_px": COMOVE_PX, "phase_min_px": PHASE_MIN_PX,
            "phase_miss_px": PHASE_MISS_PX, "highpass_px": HIGHPASS_PX,
            "off_margin_px": OFF_MARGIN_PX, "off_min_share": OFF_MIN_SHARE,
            "flow": "OpenCV DIS, medium preset"}


@dataclass(frozen=True)
class WindowStats:
    """The statistics of one window; None where a statistic is not defined for it."""

    frames: int
    contact: bool
    moving: bool
    displacement_px: float | None = None
    translation_r2: float | None = None
    co_moving_share: float | None = None
    rotation_deg: float | None = None
    strain_ratio: float | None = None
    largest_step_share: float | None = None
    speed_cv: float | None = None
    phase_miss: bool | None = None
    contact_change: bool | None = None
    imprint_hp_rms: float | None = None
    off_contact_hp_rms: float | None = None
    temporal_noise: float | None = None


def grey(frames: np.ndarray) -> np.ndarray:
    """(T, H, W, 3) uint8 RGB -> (T, H, W) float32 grey in DN."""
    w = np.array([0.299, 0.587, 0.114], np.float32)
    return np.asarray(frames, np.float32) @ w


def _blur(img: np.ndarray, sigma: float) -> np.ndarray:
    import cv2

    return cv2.GaussianBlur(img, (0, 0), sigma)


def _flows(g: np.ndarray) -> np.ndarray:
    """(T, H, W, 2) DIS flow from frame 0 to each frame (frame 0's is zero)."""
    import cv2

    g8 = np.clip(np.rint(g), 0, 255).astype(np.uint8)
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    out = np.zeros((*g.shape, 2), np.float32)
    for t in range(1, len(g)):
        out[t] = dis.calc(g8[0], g8[t], None)
    return out


def _eroded(mask: np.ndarray) -> np.ndarray:
    """The mask eroded by EDGE_PX, or the mask itself when too little of it is left."""
    import cv2

    k = np.ones((2 * EDGE_PX + 1,) * 2, np.uint8)
    inner = cv2.erode(mask.astype(np.uint8), k).astype(bool)
    return inner if inner.sum() >= MIN_REGION_SHARE * mask.size else mask


def _rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(values, dtype=np.float64))))


def affine_motion(u: np.ndarray, pts: np.ndarray) -> tuple[float, float]:
    """(rotation in degrees, largest principal strain) of the least-squares affine fit of
    displacements u (N, 2) at points pts (N, 2), by polar decomposition of I + A."""
    x = pts - pts.mean(axis=0)
    design = np.column_stack([np.ones(len(x)), x])
    beta, *_ = np.linalg.lstsq(design, u.astype(np.float64), rcond=None)
    f = np.eye(2) + beta[1:].T
    w, s, vt = np.linalg.svd(f)
    if np.linalg.det(w @ vt) < 0:  # a reflection: not a motion of the gel; keep the rotation
        w[:, -1] *= -1
        s[-1] *= -1
    r = w @ vt
    rotation = abs(math.degrees(math.atan2(r[1, 0], r[0, 0])))
    return rotation, float(np.max(np.abs(s - 1.0)))


def step_statistics(medians: np.ndarray) -> tuple[float | None, float | None]:
    """(largest-step share, speed CV) of the per-frame median displacements (T, 2)."""
    steps = np.linalg.norm(np.diff(medians, axis=0), axis=1)
    total = float(steps.sum())
    if total <= 0 or not len(steps):
        return None, None
    return float(steps.max() / total), float(steps.std() / steps.mean())


def window_stats(frames: np.ndarray, reference: np.ndarray) -> WindowStats:
    """The statistics of a (T, H, W, 3) uint8 window against a no-contact reference frame."""
    import cv2

    g = grey(frames)
    t_n, h, w = g.shape
    ref = _blur(grey(reference[None])[0], CONTACT_BLUR_PX)
    contacts = np.stack([np.abs(_blur(x, CONTACT_BLUR_PX) - ref) > CONTACT_DN for x in g])
    areas = contacts.reshape(t_n, -1).sum(axis=1)
    present = areas >= MIN_CONTACT_SHARE * h * w
    union = contacts.any(axis=0)
    if present.any():
        k = int(np.argmax(areas))
        off = ~cv2.dilate(union.astype(np.uint8), np.ones((2 * OFF_MARGIN_PX + 1,) * 2,
                                                          np.uint8)).astype(bool)
    else:
        k, off = 0, np.ones((h, w), bool)
    hp = g[k] - _blur(g[k], HIGHPASS_PX)
    imprint = _rms(hp[contacts[k]]) if present[k] else None
    enough_off = off.sum() >= OFF_MIN_SHARE * h * w
    off_hp = _rms(hp[off]) if enough_off else None
    noise = (float(np.sqrt(np.mean(g[:, off].var(axis=0, ddof=1, dtype=np.float64))))
             if enough_off and t_n > 1 else None)
    base = dict(frames=t_n, imprint_hp_rms=imprint, off_contact_hp_rms=off_hp,
                temporal_noise=noise)
    if not present.any() or t_n < 2:
        return WindowStats(contact=bool(present.any()), moving=False, **base)
    base["contact_change"] = bool(not present.all())
    region = _eroded(contacts[0] if present[0] else union)
    flows = _flows(g)
    u_t = flows[:, region]  # (T, N, 2)
    medians = np.median(u_t, axis=1)
    m = medians[-1]
    disp = float(np.hypot(*m))
    if disp <= MOVING_PX:
        return WindowStats(contact=True, moving=False, displacement_px=disp, **base)
    u = u_t[-1].astype(np.float64)
    r2 = 1.0 - float(np.sum((u - u.mean(axis=0)) ** 2) / max(np.sum(u ** 2), 1e-12))
    near = np.linalg.norm(u - m, axis=1) <= max(COMOVE_REL * disp, COMOVE_PX)
    ys, xs = np.nonzero(region)
    rotation, strain = affine_motion(u, np.column_stack([xs, ys]).astype(np.float64))
    radius = math.sqrt(region.sum() / math.pi)
    largest, cv = step_statistics(medians.astype(np.float64))
    miss = None
    if disp > PHASE_MIN_PX:
        hann = cv2.createHanningWindow((w, h), cv2.CV_32F)
        (sx, sy), _ = cv2.phaseCorrelate(g[0], g[-1], hann)
        miss = bool(math.hypot(sx, sy) < PHASE_MISS_PX)
    return WindowStats(contact=True, moving=True, displacement_px=disp, translation_r2=r2,
                       co_moving_share=float(near.mean()), rotation_deg=rotation,
                       strain_ratio=strain * radius / disp, largest_step_share=largest,
                       speed_cv=cv, phase_miss=miss, **base)
