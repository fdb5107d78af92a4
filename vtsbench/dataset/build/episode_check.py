"""What an episode writer is given, checked one frame and one episode at a time: every refusal
is one line naming the episode and frame and why (frames of another size, dtype or channel
count than the first, timestamps that do not increase or are not finite, labels out of range,
NaN or infinite depth, a slip onset outside the take, names and values of extra columns)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ...errors import VtsError
from ...labels import N_DIRECTIONS, STATES
from ..format.arrays import depth_to_int16
from ..format.episodes import SHA256_HEX, extra_name_problem
from ..format.layout import ARRAYS, RGB_ONLY

#: The longest object, session, sensor or episode name.
MAX_NAME = 200
INT64 = (-(2**63), 2**63 - 1)


@dataclass
class FrameSpec:
    """What the first frame of a dataset fixed: its size and each array's dtype as given."""

    size: tuple[int, int] | None = None
    dtypes: dict[str, str] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"size": None if self.size is None else list(self.size),
                "dtypes": dict(self.dtypes)}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> FrameSpec:
        size = d.get("size")
        return cls(None if size is None else (int(size[0]), int(size[1])),
                   dict(d.get("dtypes", {})))


def check_arrays_choice(arrays: Any) -> tuple[str, ...]:
    """The arrays a dataset of episodes holds: ("rgb",) or ("rgb", "depth", "contact")."""
    got = tuple(arrays) if isinstance(arrays, list | tuple) else (arrays,)
    if got not in (RGB_ONLY, ARRAYS):
        raise VtsError(f"arrays must be {RGB_ONLY} or {ARRAYS} (depth and contact come "
                       f"together), got {got!r}")
    return got


def check_fps(fps: Any, where: str = "fps") -> float:
    """A frame rate: a finite number > 0."""
    if isinstance(fps, bool) or not isinstance(fps, int | float | np.integer | np.floating) or (
            not math.isfinite(float(fps)) or float(fps) <= 0):
        raise VtsError(f"{where}: the frame rate must be a finite number > 0, got {fps!r}")
    return float(fps)


def check_name(value: Any, what: str, where: str) -> str:
    """An object, session, sensor or episode name: non-empty text on one line."""
    if not isinstance(value, str) or not value.strip() or len(value) > MAX_NAME or any(
            ord(c) < 32 or ord(c) == 127 for c in value):
        raise VtsError(f"{where}: {what} must be a non-empty name of at most {MAX_NAME} "
                       f"characters on one line, got {value!r:.80}")
    return value


def check_sha256(value: Any, where: str) -> str | None:
    """A calibration digest: None or 64 lowercase hex digits."""
    if value is None:
        return None
    if not isinstance(value, str) or len(value) != 64 or not set(value) <= SHA256_HEX:
        raise VtsError(f"{where}: calibration_sha256 must be a sha256 (64 lowercase hex "
                       f"digits) or None, got {value!r:.80}")
    return value


def _size(shape: tuple[int, ...]) -> str:
    return "x".join(map(str, shape[:2]))


def frame_arrays(spec: FrameSpec, arrays: tuple[str, ...], where: str, rgb: Any,
                 depth: Any, contact: Any) -> dict[str, np.ndarray]:
    """The stored arrays of one frame (copies: the caller may reuse its buffers): rgb uint8,
    depth as int16 counts of the format's scale, contact bool. The first frame fixes the
    size and dtypes (recorded in spec)."""
    given = {"rgb": rgb, "depth": depth, "contact": contact}
    for name in ("depth", "contact"):
        if given[name] is not None and name not in arrays:
            raise VtsError(f"{where}: {name} given, but the dataset was created with "
                           f"arrays={arrays!r}")
        if given[name] is None and name in arrays:
            raise VtsError(f"{where}: no {name} (the dataset was created with "
                           f"arrays={arrays!r})")
    out = {}
    for name in arrays:
        a = np.asarray(given[name])
        want = 3 if name == "rgb" else 2
        if a.ndim != want or (name == "rgb" and a.shape[2] != 3):
            what = (f"has {a.shape[2]} channels, expected 3 (RGB)" if name == "rgb"
                    and a.ndim == 3 else f"of shape {a.shape}, expected "
                    f"{'(H, W, 3)' if name == 'rgb' else '(H, W)'}")
            raise VtsError(f"{where}: {name} {what}")
        if spec.size is not None and a.shape[:2] != spec.size:
            raise VtsError(f"{where}: {name} of size {_size(a.shape)} differs from the first "
                           f"frame's {_size(spec.size)} (every frame of a dataset has one size)")
        if name in spec.dtypes and str(a.dtype) != spec.dtypes[name]:
            raise VtsError(f"{where}: {name} dtype {a.dtype} differs from the first frame's "
                           f"{spec.dtypes[name]}")
        out[name] = _stored(name, a, where)
    if spec.size is None:
        spec.size = (int(out["rgb"].shape[0]), int(out["rgb"].shape[1]))
    for name in arrays:
        spec.dtypes.setdefault(name, str(np.asarray(given[name]).dtype))
    return out


def _stored(name: str, a: np.ndarray, where: str) -> np.ndarray:
    """One array of a frame as stored."""
    if name == "rgb":
        if a.dtype != np.uint8:
            raise VtsError(f"{where}: rgb dtype {a.dtype}, expected uint8 (0..255 RGB)")
        return np.array(a, np.uint8, order="C", copy=True)
    if name == "contact":
        if a.dtype != np.bool_ and a.dtype != np.uint8:
            raise VtsError(f"{where}: contact dtype {a.dtype}, expected bool or uint8")
        return np.ascontiguousarray(a != 0)
    if a.dtype.kind not in "fiu":
        raise VtsError(f"{where}: depth dtype {a.dtype}, expected a real number type (mm)")
    bad = ~np.isfinite(a) if a.dtype.kind == "f" else np.zeros(a.shape, bool)
    if bad.any():
        raise VtsError(f"{where}: depth has {int(bad.sum())} NaN or infinite value(s) (mm "
                       "must be finite; store an unknown depth as 0)")
    return depth_to_int16(a)


def check_timestamp(value: Any, previous: float | None, where: str) -> float:
    """A timestamp in seconds from the episode start: finite, >= 0, after the previous one."""
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise VtsError(f"{where}: timestamp must be a number of seconds, got {value!r:.80}")
    t = float(value)
    if not math.isfinite(t):
        raise VtsError(f"{where}: timestamp {t!r} is not finite")
    if t < 0:
        raise VtsError(f"{where}: timestamp {t!r} is negative (seconds from the episode start)")
    if previous is not None and t <= previous:
        what = "repeats" if t == previous else "goes back from"
        raise VtsError(f"{where}: timestamp {t!r} {what} the previous frame's ({previous!r}); "
                       "timestamps must be strictly increasing")
    return t


def check_labels(state: Any, direction: Any, where: str) -> tuple[int | None, int | None]:
    """(state index, direction) of a frame: state None, a name of labels.STATES or its index;
    direction None or 0..7, only on a frame whose state is slip."""
    if state is None:
        s = None
    elif isinstance(state, str) and state in STATES:
        s = STATES.index(state)
    elif (isinstance(state, int | np.integer) and not isinstance(state, bool)
          and 0 <= int(state) < len(STATES)):
        s = int(state)
    else:
        raise VtsError(f"{where}: state {state!r:.80} is none of {', '.join(STATES)} (or their "
                       f"index 0..{len(STATES) - 1}, or None)")
    if direction is None:
        return s, None
    if (isinstance(direction, bool) or not isinstance(direction, int | np.integer)
            or not 0 <= int(direction) < N_DIRECTIONS):
        raise VtsError(f"{where}: direction {direction!r:.80} is not a bin 0..{N_DIRECTIONS - 1}"
                       " (or None)")
    if s != STATES.index("slip"):
        raise VtsError(f"{where}: a direction ({int(direction)}) on a frame whose state is "
                       f"{'unknown' if s is None else STATES[s]}, not slip")
    return s, int(direction)


def _kind(value: Any) -> str | None:
    if value is None:
        return None
    if isinstance(value, bool | np.bool_):
        return "bool"
    if isinstance(value, int | np.integer):
        return "int"
    if isinstance(value, float | np.floating):
        return "float"
    if isinstance(value, str):
        return "string"
    return "?"


def check_extra(extra: Mapping[str, Any], kinds: dict[str, str], taken: set[str],
                where: str) -> dict[str, Any]:
    """Per-frame values: plain names, values None, bool, int (int64), float or str, one kind a
    column (an int column takes floats and becomes float). Updates kinds; returns the values
    as Python scalars."""
    out = {}
    for name, value in extra.items():
        bad = extra_name_problem(name)
        if bad is None and name in taken:
            bad = f"{name!r} is already an episode metadata column"
        if bad:
            raise VtsError(f"{where}: extra column {bad}")
        k = _kind(value)
        if k == "?":
            raise VtsError(f"{where}: extra {name!r} is a {type(value).__name__}; per-frame "
                           "values are None, bool, int, float or str")
        if k == "int" and not INT64[0] <= int(value) <= INT64[1]:
            raise VtsError(f"{where}: extra {name!r} = {value} does not fit in int64")
        have = kinds.get(name)
        if k is not None and have is not None and k != have and {k, have} != {"int", "float"}:
            raise VtsError(f"{where}: extra {name!r} is {k}, earlier frames gave {have}")
        if k is not None:
            kinds[name] = "float" if "float" in (k, have) else k
        out[name] = value.item() if isinstance(value, np.generic) else value
    return out


def check_meta(meta: Mapping[str, Any], frame_columns: set[str], where: str
               ) -> dict[str, str | None]:
    """An episode's own metadata: plain names, values None, str, int, float or bool (stored
    as strings, as the other indexes store the recordings' own fields)."""
    out: dict[str, str | None] = {}
    for name, value in meta.items():
        bad = extra_name_problem(name)
        if bad is None and name in frame_columns:
            bad = f"{name!r} is already a per-frame column"
        if bad:
            raise VtsError(f"{where}: metadata column {bad}")
        if value is not None and _kind(value) in (None, "?"):
            raise VtsError(f"{where}: metadata {name!r} is a {type(value).__name__}; values "
                           "are None, str, int, float or bool (stored as text)")
        out[name] = None if value is None else str(value.item() if isinstance(
            value, np.generic) else value)
    return out


def check_onset(onset: Any, ts: np.ndarray, where: str) -> float | None:
    """slip_onset_s: None, or a time between the first and the last frame's timestamps."""
    if onset is None:
        return None
    if isinstance(onset, bool) or not isinstance(onset, int | float | np.integer | np.floating):
        raise VtsError(f"{where}: slip_onset_s must be seconds (a number) or None, got "
                       f"{onset!r:.80}")
    t = float(onset)
    if not math.isfinite(t) or not ts[0] <= t <= ts[-1]:
        raise VtsError(f"{where}: slip_onset_s {t!r} is outside the take ({float(ts[0])!r} to "
                       f"{float(ts[-1])!r} s)")
    return t
