"""Planning: which entry gets which object, state and session, and each entry's random scene.

Every entry draws from its own generator, seeded by (seed, kind, number) and nothing else, so
an entry's files do not depend on which worker renders it or in which order.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..labels import STATES
from .motion import Motion, place_path, sample_motion, sequence_scene, slip_range
from .objects import BALL, BALL_RADIUS_MM, OBJECTS, ObjectInstance, random_instance
from .scene import Effects, Scene

if TYPE_CHECKING:
    from .appearance import Appearance
    from .mechanics import Mechanics

KIND_CODES = {"static": 0, "sequence": 1, "press": 2}
_SESSION_CODE = 3
_PLAN_CODE = 4
_PREFIX = {"static": "static", "sequence": "seq", "press": "press"}

#: Calibration presses: depth range (mm) and clearance (mm) between the contact and the border.
PRESS_DEPTH_MM = (0.1, 1.2)
PRESS_CLEARANCE_MM = 0.15
#: Smallest contact radius (px) of the shallowest calibration press worth recording.
MIN_PRESS_RADIUS_PX = 4.0
MIN_SIZE_PX = 32
#: Generator versions: 1 rigid shifts at constant speed on a clean sensor; 2 contact mechanics,
#: uneven speed, contact made or lost, the gel's fixed pattern and a real camera.
GENERATORS = (1, 2)
LATEST_GENERATOR = 2
#: What `vtsbench simulate` writes unless told: generator 2, the simulator of benchmark v2 and its
#: published results (generator 1 stays reproducible by name).
DEFAULT_GENERATOR = 2


@dataclass(frozen=True)
class EntryPlan:
    """What one entry is: kind, 1-based number within the kind, session, object, state."""

    kind: str
    number: int
    session: int
    object: str
    state: str | None = None

    @property
    def id(self) -> str:
        """The entry id, e.g. seq-00001."""
        return f"{_PREFIX[self.kind]}-{self.number:05d}"


def entry_rng(seed: int, kind: str, number: int) -> np.random.Generator:
    """The generator of one entry, independent of every other entry."""
    return np.random.default_rng(np.random.SeedSequence([seed, KIND_CODES[kind], number]))


def session_rng(seed: int, session: int) -> np.random.Generator:
    """The generator of one session's capture settings and background frame."""
    return np.random.default_rng(np.random.SeedSequence([seed, _SESSION_CODE, session]))


def _balanced(rng: np.random.Generator, n: int, k: int) -> list[int]:
    """n values cycling over 0..k-1, shuffled: balanced counts, no pattern tied to position."""
    values = [i % k for i in range(n)]
    return [values[i] for i in rng.permutation(n)] if n else []


def _balanced_per_state(rng: np.random.Generator, n: int, k: int) -> list[int]:
    """Objects of n sequences whose states cycle over STATES: balanced within each state, so
    that any set of objects holds as many sequences of every state (a held-out test part is
    then balanced by construction, 400 a state for 5 of 15 objects in 3,600 sequences)."""
    out = [0] * n
    for st in range(len(STATES)):
        at = list(range(st, n, len(STATES)))
        for i, obj in zip(at, _balanced(rng, len(at), k), strict=True):
            out[i] = obj
    return out


def make_plans(seed: int, n_static: int, n_sequences: int, n_presses: int, n_objects: int,
               n_sessions: int, per_state: bool = False) -> list[EntryPlan]:
    """All entries in manifest order: static frames, sequences, presses.

    Objects and sessions are balanced and shuffled independently per kind (so neither is tied
    to the other or to the sequence state); sequence states cycle static, press, slip. With
    `per_state` (generator 2) the sequences' objects are balanced within each state as well.
    """
    plans: list[EntryPlan] = []
    for kind, n in (("static", n_static), ("sequence", n_sequences), ("press", n_presses)):
        rng = np.random.default_rng(np.random.SeedSequence([seed, _PLAN_CODE, KIND_CODES[kind]]))
        objects = _balanced_per_state(rng, n, n_objects) if per_state and kind == "sequence" \
            else _balanced(rng, n, n_objects)
        sessions = _balanced(rng, n, n_sessions)
        for i in range(n):
            name = BALL.name if kind == "press" else OBJECTS[objects[i]].name
            state = STATES[i % 3] if kind == "sequence" else None
            plans.append(EntryPlan(kind, i + 1, sessions[i], name, state))
    return plans


def ball_contact_radius_mm(depth_mm: float) -> float:
    """Radius of the rigid overlap of the calibration ball at a depth."""
    return math.sqrt(max(2.0 * BALL_RADIUS_MM * depth_mm - depth_mm * depth_mm, 0.0))


def max_press_depth_mm(size: tuple[int, int], mm_per_px: float) -> float:
    """Deepest calibration press whose contact stays inside the frame (with clearance)."""
    # centres lie in [reach, size - 1 - reach] (pixel centres 0..size-1): half of size - 1
    a = (min(size) - 1) * mm_per_px / 2.0 - PRESS_CLEARANCE_MM
    if a >= BALL_RADIUS_MM:
        return PRESS_DEPTH_MM[1]
    if a <= 0.0:
        return 0.0
    return min(PRESS_DEPTH_MM[1], BALL_RADIUS_MM - math.sqrt(BALL_RADIUS_MM**2 - a * a))


def size_problem(size: tuple[int, int], mm_per_px: float, presses: bool) -> str | None:
    """Why a frame size and scale cannot be simulated, or None."""
    from ..limits import MAX_SIDE_PX

    height, width = size
    if height < MIN_SIZE_PX or width < MIN_SIZE_PX:
        return f"frame size {height}x{width} is too small (at least {MIN_SIZE_PX}x{MIN_SIZE_PX})"
    if height > MAX_SIDE_PX or width > MAX_SIDE_PX:
        return (f"--size {height}x{width} is too large (at most {MAX_SIDE_PX}x{MAX_SIDE_PX})")
    if not mm_per_px > 0.0 or not math.isfinite(mm_per_px):
        return f"mm_per_px must be a positive number, got {mm_per_px}"
    if presses:
        r_px = ball_contact_radius_mm(PRESS_DEPTH_MM[0]) / mm_per_px
        if r_px < MIN_PRESS_RADIUS_PX:
            return (f"{mm_per_px} mm/px is too coarse for calibration presses: a {BALL_RADIUS_MM}"
                    f" mm ball pressed {PRESS_DEPTH_MM[0]} mm touches only {r_px:.1f} px "
                    f"(at least {MIN_PRESS_RADIUS_PX:g}); use a smaller --mm-per-px or --presses 0")
        if max_press_depth_mm(size, mm_per_px) < PRESS_DEPTH_MM[0]:
            need = 2 * (ball_contact_radius_mm(PRESS_DEPTH_MM[0]) + PRESS_CLEARANCE_MM)
            return (f"a {height}x{width} frame at {mm_per_px} mm/px ({height * mm_per_px:.2f} x "
                    f"{width * mm_per_px:.2f} mm) is too small for a {BALL_RADIUS_MM} mm ball "
                    f"pressed {PRESS_DEPTH_MM[0]} mm (needs {need:.2f} mm); use a larger --size "
                    "or --mm-per-px, or --presses 0")
    return None


def _generation(scene: Scene, generator: int, appearance: Appearance | None = None) -> Scene:
    """The scene with the sensor of its generator: version 2 adds the gel mechanics and the
    sensor's appearance (fixed pattern, camera; the default gel's unless given); version 1
    leaves it as it is."""
    if generator < 2:
        return scene
    from .appearance import sensor_appearance
    from .mechanics import Mechanics

    return dataclasses.replace(scene, mechanics=scene.mechanics or Mechanics(),
                               appearance=appearance or sensor_appearance())


def static_scene(plan: EntryPlan, rng: np.random.Generator, size: tuple[int, int],
                 mm_per_px: float, generator: int = 1,
                 appearance: Appearance | None = None) -> Scene:
    """A single frame of a held object at a random pose, place and depth."""
    from .objects import by_name

    cls = by_name(plan.object)
    obj = random_instance(cls, rng)
    depth = float(rng.uniform(*cls.depth_mm))
    center = place_path(Motion(0.0, 0.0, depth, depth), rng, size, mm_per_px)
    return _generation(Scene(obj, (center,), (depth,), size, mm_per_px,
                             Effects(texture=cls.texture is not None)), generator, appearance)


def sequence_plan_scene(plan: EntryPlan, rng: np.random.Generator, size: tuple[int, int],
                        mm_per_px: float, n_frames: int, generator: int = 1,
                        appearance: Appearance | None = None,
                        mechanics: Mechanics | None = None) -> tuple[Scene, Motion]:
    """A sequence of the plan's intended state, and the motion that made it (generator 2:
    with the given sensor appearance and gel mechanics, the defaults unless given)."""
    from .objects import by_name

    cls = by_name(plan.object)
    obj = random_instance(cls, rng)
    motion = sample_motion(plan.state or "static", rng, cls.depth_mm, generator)
    if generator >= 2 and plan.state in ("press", "slip"):
        return _moving_scene_v2(obj, motion, plan.state, rng, size, mm_per_px, n_frames,
                                appearance, mechanics)
    start = place_path(motion, rng, size, mm_per_px)
    scene = sequence_scene(obj, motion, start, n_frames, size, mm_per_px)
    if generator >= 2:  # a held object's tangential load shears the gel
        from .mechanics import Mechanics, held_path

        mech = mechanics or Mechanics()
        scene = dataclasses.replace(scene, mechanics=mech,
                                    path=held_path(mech, rng, n_frames, mm_per_px))
    return _generation(scene, generator, appearance), motion


def _contact_change(state: str, motion: Motion, prog: tuple[float, ...],
                    rng: np.random.Generator, share: float) -> tuple[str | None, int]:
    """Whether contact is made or lost inside the window, and the frame it changes at.

    'made' at k: no contact before frame k; 'lost' at k: no contact from frame k. A slip's
    change frame leaves at least generator 2's smallest slip (slip_range(2)[0]) in contact, so
    that the window stays a slip under the labelling rule.
    """
    n = len(prog)
    if n < 3 or rng.random() >= share:
        return None, 0
    if state == "press":
        return "made", int(rng.integers(1, n - 1))
    dist = math.hypot(motion.dx_mm, motion.dy_mm)
    made = rng.random() < 0.5
    least = slip_range(2)[0]
    if made:
        ks = [k for k in range(1, n - 1) if (1.0 - prog[k]) * dist >= least]
    else:
        ks = [k for k in range(2, n) if prog[k - 1] * dist >= least]
    if not ks:
        return None, 0
    return ("made" if made else "lost"), int(ks[int(rng.integers(len(ks)))])


def _moving_scene_v2(obj: ObjectInstance, motion: Motion, state: str,
                     rng: np.random.Generator, size: tuple[int, int], mm_per_px: float,
                     n_frames: int, appearance: Appearance | None = None,
                     mechanics: Mechanics | None = None) -> tuple[Scene, Motion]:
    """A generator-2 press or slip: uneven speed, rotation, partial slip of the gel, and
    contact made or lost inside the window (docs/simulator.md, "Generator 2")."""
    from .mechanics import Mechanics, contact_path, progress, step_weights

    mech = mechanics or Mechanics()
    kind, weights = step_weights(mech, rng, n_frames - 1)
    prog = progress(weights)
    d0, d1 = motion.depth0_mm, motion.depth1_mm
    depths = [d0 + (d1 - d0) * p for p in prog]
    change, k = _contact_change(state, motion, prog, rng, mech.contact_change_share)
    if change is not None:
        above = -(float(rng.uniform(*mech.lift_mm)) + obj.texture_bound_mm)
        gone = range(k) if change == "made" else range(k, n_frames)
        for t in gone:
            depths[t] = above
    motion = dataclasses.replace(motion, progress=prog, depth_path=tuple(depths),
                                 depth0_mm=depths[0], depth1_mm=depths[-1])
    total_px = (motion.dx_mm / mm_per_px, -motion.dy_mm / mm_per_px)
    path = contact_path(mech, rng, prog, total_px, mm_per_px,
                        k if change == "made" else 0, kind, change)
    start = place_path(motion, rng, size, mm_per_px)
    effects = Effects(texture=obj.cls.texture is not None, motion=True)
    scene = Scene(obj, motion.centers(start, n_frames, mm_per_px), motion.depths(n_frames), size,
                  mm_per_px, effects, mechanics=mech, path=path)
    return _generation(scene, 2, appearance), motion


def press_scene(rng: np.random.Generator, size: tuple[int, int], mm_per_px: float,
                generator: int = 1, appearance: Appearance | None = None,
                depth_mm: float | None = None) -> Scene:
    """A calibration press: the smooth ball at a random depth (or depth_mm, drawing nothing for
    it), its contact inside the frame."""
    height, width = size
    depth = float(rng.uniform(PRESS_DEPTH_MM[0], max_press_depth_mm(size, mm_per_px))) \
        if depth_mm is None else float(depth_mm)
    reach = (ball_contact_radius_mm(depth) + PRESS_CLEARANCE_MM) / mm_per_px
    cx = float(rng.uniform(min(reach, (width - 1) / 2), max(reach, width - 1 - reach)))
    cy = float(rng.uniform(min(reach, (height - 1) / 2), max(reach, height - 1 - reach)))
    obj = random_instance(BALL, rng)
    return _generation(Scene(obj, ((cx, cy),), (depth,), size, mm_per_px,
                             Effects(texture=False)), generator, appearance)
