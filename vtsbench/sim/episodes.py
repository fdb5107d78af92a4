"""Continuous simulated takes: hold, press, hold in contact, slip onset and slip, release, with
exact per-frame labels and the slip's onset time (docs/simulator.md, "Continuous episodes").

One take is one generator-2 scene over all its frames (the simulator's current defaults: gel
mechanics, partial slip, rotation, uneven speed, the sensor's gel pattern and camera): the
object's commanded translation and depth per frame place it, and the labels come from the
same motion. A frame's state is `vtsbench.labels.label_contact_window` of the motion over the
`label_window` frames ending at it (the window a causal monitor of that length sees), because
the rule's thresholds are over a window: one frame step of a slip (0.06-0.4 mm per 8-frame
window) is 0.01-0.06 mm, under the 0.05 mm slip threshold. Where the rule gives no state, the
phase decides: no contact in the whole window (the object above the gel) is static (nothing
on the sensor moves), a release (contact lost or indentation falling) stays unknown (None), as
the rule says. The onset is the first slip frame; a take without slip has none.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..errors import VtsError
from ..labels import STATES, direction_class, label_contact_window
from .motion import Motion, place_path, slip_range

if TYPE_CHECKING:
    from .appearance import Appearance
    from .optics import Capture

#: Phases of a take, in order (a take without slip skips "slip").
PHASES: tuple[str, ...] = ("hold", "press", "contact", "slip", "release")
#: Frames per labelling window: the paper's 8-frame sequences, the recipes' window.
LABEL_WINDOW = 8
#: Share of a take's frames in each phase (drawn uniformly in these ranges, then the slip, or
#: the contact hold of a take without slip, takes the rest).
HOLD_SHARE = (0.10, 0.18)
PRESS_SHARE = (0.12, 0.2)
CONTACT_SHARE = (0.12, 0.2)
RELEASE_SHARE = (0.08, 0.12)
#: Share of takes whose first hold is in light contact (the rest: above the gel).
LIGHT_CONTACT_SHARE = 0.5
#: The frame field of view (mm across the width) when no scale is given: the simulator's
#: default frame (640 px at 0.03 mm/px).
FIELD_WIDTH_MM = 19.2
_EPISODE_CODE = 5
_EPISODE_PLAN_CODE = 6
_SEGMENT = LABEL_WINDOW - 1  # frame steps of one generator-2 slip draw


@dataclass(frozen=True)
class EpisodePlan:
    """What one take is: its number (0-based), object, session and whether it slips."""

    number: int
    object: str
    session: int
    slip: bool


@dataclass
class SimEpisode:
    """A rendered take with its exact per-frame truth.

    states: a name of STATES or None per frame; directions: the slip bin where the state is
    slip; phase: the phase per frame; position_mm: (T, 2) the object's translation from frame 0
    (x right, y up); depth_mm: (T,) its commanded indentation (below 0: above the gel);
    in_contact: (T,) bool from the rendered contact; contact_px: (T, 2) its centroid (px, NaN
    without contact); depth/contact: the rendered truth maps (T, H, W) when asked."""

    plan: EpisodePlan
    fps: float
    frames: np.ndarray
    states: list[str | None]
    directions: list[int | None]
    phase: list[str]
    position_mm: np.ndarray
    depth_mm: np.ndarray
    in_contact: np.ndarray
    contact_px: np.ndarray
    onset_frame: int | None
    direction: int | None
    mm_per_px: float
    label_window: int = LABEL_WINDOW
    depth: np.ndarray | None = None
    contact: np.ndarray | None = None
    meta: dict = dataclasses.field(default_factory=dict)

    @property
    def timestamps(self) -> np.ndarray:
        """Seconds from the take's start: frame k at k / fps."""
        return np.arange(len(self.frames), dtype=np.float64) / self.fps

    @property
    def slip_onset_s(self) -> float | None:
        """When slip starts (the first slip frame's time), None without slip."""
        return None if self.onset_frame is None else self.onset_frame / self.fps


def default_mm_per_px(size: tuple[int, int]) -> float:
    """The scale that gives a frame of `size` the simulator's default field of view."""
    return FIELD_WIDTH_MM / size[1]


def episode_rng(seed: int, number: int) -> np.random.Generator:
    """The generator of one take, independent of every other take and of the worker."""
    return np.random.default_rng(np.random.SeedSequence([seed, _EPISODE_CODE, number]))


def plan_episodes(seed: int, n_episodes: int, n_objects: int, n_sessions: int,
                  no_slip_share: float = 0.25) -> list[EpisodePlan]:
    """Takes cycling over the first n_objects objects, sessions balanced and shuffled; every
    round(1 / no_slip_share)-th take of each object has no slip."""
    from .objects import OBJECTS

    if not 1 <= n_objects <= len(OBJECTS):
        raise VtsError(f"--objects must be between 1 and {len(OBJECTS)}, got {n_objects}")
    if not 0.0 <= no_slip_share <= 1.0:
        raise VtsError(f"no_slip_share must be in [0, 1], got {no_slip_share}")
    rng = np.random.default_rng(np.random.SeedSequence([seed, _EPISODE_PLAN_CODE]))
    objects = [i % n_objects for i in range(n_episodes)]
    sessions = [int(v) for v in rng.permutation([i % n_sessions for i in range(n_episodes)])]
    plans = []
    seen: dict[int, int] = {}
    period = round(1.0 / no_slip_share) if no_slip_share > 0 else 0
    for i, obj in enumerate(objects):
        k = seen.get(obj, 0)  # the object's k-th take: every period-th has no slip, from a
        seen[obj] = k + 1  # take that differs between objects
        still = period > 0 and (k + obj) % period == period - 1
        plans.append(EpisodePlan(i, OBJECTS[obj].name, sessions[i], not still))
    return plans


def _phase_lengths(rng: np.random.Generator, n: int, slip: bool) -> dict[str, int]:
    """Frames per phase of a take of n frames."""
    def draw(share: tuple[float, float]) -> int:
        return max(2, round(float(rng.uniform(*share)) * n))

    out = {"hold": draw(HOLD_SHARE), "press": draw(PRESS_SHARE),
           "contact": draw(CONTACT_SHARE), "release": draw(RELEASE_SHARE)}
    rest = n - sum(out.values())
    if rest < (2 * LABEL_WINDOW if slip else 0):
        raise VtsError(f"a take of {n} frames is too short for its phases (at least "
                       f"{_min_frames()} frames: more --seconds or a higher --fps)")
    if slip:
        out["slip"] = rest
    else:
        out["contact"] += rest
    return {p: out.get(p, 0) for p in PHASES}


def _min_frames() -> int:
    """The fewest frames a take with slip can have."""
    return math.ceil(2 * LABEL_WINDOW / (1.0 - HOLD_SHARE[1] - PRESS_SHARE[1] - CONTACT_SHARE[1]
                                         - RELEASE_SHARE[1])) + 8


def _ramp(rng: np.random.Generator, mech, n: int) -> np.ndarray:
    """n + 1 shares from 0 to 1 over n frame steps along a generator-2 speed profile."""
    from .mechanics import progress, step_weights

    if n <= 0:
        return np.zeros(1)
    _, w = step_weights(mech, rng, n)
    return np.asarray(progress(w))


def _slip_track(rng: np.random.Generator, mech, n: int) -> tuple[np.ndarray, float]:
    """Distance along the slip (mm) at each of n + 1 frames from the onset of motion: one
    generator-2 draw (distance in slip_range(2), a speed profile) every 7 frame steps, so that
    every 8-frame window of the slip moves as a generator-2 slip window does."""
    lo, hi = slip_range(2)
    out = [0.0]
    while len(out) < n + 1:
        steps = min(_SEGMENT, n + 1 - len(out))
        dist = float(math.exp(rng.uniform(math.log(lo), math.log(hi))))
        shares = _ramp(rng, mech, _SEGMENT)[1:steps + 1]
        out += [out[-1] + dist * s for s in shares.tolist()]
    track = np.asarray(out[:n + 1])
    return track, float(track[-1])


def frame_labels(position_mm: np.ndarray, depth_mm: np.ndarray, in_contact: np.ndarray,
                 phase: list[str], window: int = LABEL_WINDOW
                 ) -> tuple[list[str | None], list[int | None]]:
    """State and direction per frame: the labelling rule on the `window` frames ending at the
    frame, by phase where the rule is undefined (module docstring)."""
    states: list[str | None] = []
    dirs: list[int | None] = []
    for t in range(len(depth_mm)):
        a = max(0, t - window + 1)
        lab = label_contact_window([tuple(p) for p in position_mm[a:t + 1].tolist()],
                                   depth_mm[a:t + 1].tolist(), in_contact[a:t + 1].tolist())
        state = lab.state
        if state is None and not in_contact[a:t + 1].any():
            state = "static"  # nothing touches the gel: the sensor's image is still
        states.append(state)
        dirs.append(lab.direction if state == "slip" else None)
    return states, dirs


def episode_scene(plan: EpisodePlan, rng: np.random.Generator, size: tuple[int, int],
                  mm_per_px: float, n_frames: int, appearance: Appearance | None = None):
    """The scene of a take (one generator-2 scene over every frame), its per-frame phase,
    position (mm, y up) and commanded depth (mm)."""
    from .mechanics import Mechanics, contact_path, held_path
    from .objects import by_name, random_instance
    from .plan import _generation
    from .scene import Effects, Scene

    mech = Mechanics()
    cls = by_name(plan.object)
    obj = random_instance(cls, rng)
    lengths = _phase_lengths(rng, n_frames, plan.slip)
    phase = [p for p in PHASES for _ in range(lengths[p])]
    lo, hi = cls.depth_mm
    d1 = float(rng.uniform(max(lo, 0.2 * hi), hi))  # the grasp's indentation
    lift = -(float(rng.uniform(*mech.lift_mm)) + obj.texture_bound_mm)
    light = rng.random() < LIGHT_CONTACT_SHARE
    d0 = float(rng.uniform(0.02, 0.25 * d1)) if light else lift
    depth = np.empty(n_frames)
    i = 0
    for p in PHASES:
        m = lengths[p]
        if p == "hold":
            depth[i:i + m] = d0
        elif p == "press":  # from the hold's depth to the grasp's, last frame at d1
            ramp = _ramp(rng, mech, m)[1:]
            depth[i:i + m] = d0 + (d1 - d0) * ramp
        elif p in ("contact", "slip"):
            depth[i:i + m] = d1
        else:  # release: the indentation falls until the object is off the gel
            ramp = _ramp(rng, mech, m)[1:]
            depth[i:i + m] = d1 + (lift - d1) * ramp
        i += m
    angle = float(rng.uniform(0.0, 360.0))
    along = np.zeros(n_frames)
    s0, n_slip = lengths["hold"] + lengths["press"] + lengths["contact"], lengths["slip"]
    if plan.slip:
        track, _ = _slip_track(rng, mech, n_slip)
        along[s0:s0 + n_slip] = track[1:]
        along[s0 + n_slip:] = track[-1]  # the release lifts it where it slid to
    a = math.radians(angle)
    position = np.stack([along * math.cos(a), along * math.sin(a)], axis=1)
    total = float(along[-1])
    start = place_path(Motion(position[-1, 0], position[-1, 1], d1, d1), rng, size, mm_per_px)
    centers = tuple((start[0] + float(x) / mm_per_px, start[1] - float(y) / mm_per_px)
                    for x, y in position.tolist())
    prog = tuple((along / total).tolist()) if total > 0 else (0.0,) * n_frames
    if plan.slip:  # the tangential load builds in the slip's direction until gross slip
        total_px = (position[-1, 0] / mm_per_px, -position[-1, 1] / mm_per_px)
        path = contact_path(mech, rng, prog, total_px, mm_per_px, 0, "varying")
    else:
        path = held_path(mech, rng, n_frames, mm_per_px)
    scene = Scene(obj, centers, tuple(depth.tolist()), size, mm_per_px,
                  Effects(texture=cls.texture is not None, motion=True), mechanics=mech,
                  path=path)
    meta = {"angle_deg": round(angle, 4), "slip_mm": round(total, 6),
            "grasp_depth_mm": round(d1, 6), "light_contact": bool(light),
            "phases": {p: lengths[p] for p in PHASES}}
    return _generation(scene, 2, appearance), phase, position, depth, meta


def render_episode(plan: EpisodePlan, *, seed: int, size: tuple[int, int], fps: float,
                   seconds: float, mm_per_px: float | None = None,
                   capture: Capture | None = None, appearance: Appearance | None = None,
                   truth: bool = False, label_window: int = LABEL_WINDOW) -> SimEpisode:
    """Render one take of round(fps x seconds) frames and label every frame (truth: keep the
    rendered depth and contact maps)."""
    from .scene import render

    n = round(fps * seconds)
    if n < _min_frames():
        raise VtsError(f"a take of {seconds:g} s at {fps:g} fps is {n} frames; at least "
                       f"{_min_frames()} (more --seconds or a higher --fps)")
    mpp = default_mm_per_px(size) if mm_per_px is None else float(mm_per_px)
    rng = episode_rng(seed, plan.number)
    scene, phase, position, depth, meta = episode_scene(plan, rng, size, mpp, n, appearance)
    rendered = render(scene, capture, rng)
    in_contact = rendered.contact.any(axis=(1, 2))
    states, dirs = frame_labels(position, depth, in_contact, phase, label_window)
    onset = next((t for t, s in enumerate(states) if s == "slip"), None)
    bin_ = None
    if plan.slip:
        bin_ = direction_class(float(position[-1, 0]), float(position[-1, 1]), 0.0)
    return SimEpisode(plan, float(fps), rendered.frames, states, dirs, phase, position,
                      depth, in_contact, centroids(rendered.contact), onset, bin_, mpp,
                      label_window,
                      rendered.depth_mm if truth else None,
                      rendered.contact if truth else None, meta)


def centroids(contact: np.ndarray) -> np.ndarray:
    """(T, 2) centroid (x, y) in px of each frame's contact, NaN where there is none."""
    out = np.full((len(contact), 2), np.nan)
    for t, mask in enumerate(contact):
        ys, xs = np.nonzero(mask)
        if xs.size:
            out[t] = (xs.mean(), ys.mean())
    return out


def state_indices(states: list[str | None]) -> np.ndarray:
    """States as int8 indices of STATES, -1 where unknown."""
    return np.asarray([-1 if s is None else STATES.index(s) for s in states], np.int8)
