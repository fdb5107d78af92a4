"""Sphere calibration: fit f(colour difference, x, y) -> (p, q) from ball presses, and its file.

`calibrate(folder)` reads the `press` entries of a recordings folder, takes each press's contact
circle (labelled, or found from the difference to the background), labels the pixels well inside
it with the sphere's gradients and pixels far from it with zero (see `sphere.Rim`), fits one of
the mappings of `mapping.py`, and scores the held-out presses by integrating their predicted
gradients into depth. At run time the mapping's value for a zero difference, f(0, x, y), is
subtracted, so an image equal to the background gives exactly zero gradients.

The calibration file is safetensors (no pickle): the mapping's arrays, the background (uint8,
H x W x 3) and the zero map f(0, x, y) (float32, H x W x 2) as tensors, and a JSON document under
the metadata key "vtsbench" that `schemas/calibration.schema.json` describes.
"""

from __future__ import annotations

import json
import math
import os
import struct
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import VtsError
from .mapping import METHODS, Mapping, fit_mapping, mapping_from_arrays
from .markers import (
    DotCorrection,
    MarkerSpec,
    background_dots,
    blur_difference,
    detect_markers,
    dot_blur_px,
    dot_correction,
    fill_gradients,
    left_out_of_fit,
)
from .sphere import Rim, ball_radius_px, circle_doubts, detect_circle, sphere_fields

FORMAT = "vtsbench.calibration"
FORMAT_VERSION = "1.0"
META_KEY = "vtsbench"
#: Presses needed to train (plus the held-out ones).
MIN_TRAIN = 3
#: A labelled circle up to this factor above the ball radius in pixels is a hand-marking error
#: and is clamped (sphere.Rim.max_radius_frac); beyond it the scale or ball radius is wrong.
RADIUS_TOLERANCE = 1.15
#: Training samples per press: at most this many pixels of the cap and of the flat gel.
CAP_SAMPLES = 4000
FLAT_SAMPLES = 1500
#: Default Gaussian blur (px) of the colour difference before the mapping (sensor noise).
BLUR_PX = 1.0
#: The solvers every held-out press is scored with, and the figures kept for each.
SOLVERS = ("dct", "dst", "masked")
SOLVER_KEYS = ("plane_aligned_rmse_mm", "contact_rmse_mm", "peak_depth_error_mm", "min_depth_mm",
               "negative_share", "border_abs_mm")
SCHEMA_PATH = Path(__file__).resolve().parent.parent / "schemas" / "calibration.schema.json"


def _version() -> str:
    try:
        from importlib.metadata import version

        return version("vtsbench")
    except Exception:  # not installed (running from a source tree)
        return "unknown"


@dataclass
class Calibration:
    """A fitted sensor calibration: mapping, background and zero map, with its description."""

    mapping: Mapping
    background: np.ndarray  # (H, W, 3) uint8
    zero_map: np.ndarray  # (H, W, 2) float32: f(0, x, y)
    sensor: str
    mm_per_px: tuple[float, float]
    ball_radius_mm: float
    rim: Rim = field(default_factory=Rim)
    blur_px: float = BLUR_PX
    colour_limit_dn: float = 255.0
    #: The gel's marker dots (markers.py), filled in the gradients; None: a markerless gel.
    markers: MarkerSpec | None = None
    fit: dict[str, Any] = field(default_factory=dict)
    n_presses: int = 0
    created_by: str = "vtsbench calibrate"
    vtsbench_version: str = field(default_factory=_version)
    format_version: str = FORMAT_VERSION

    @property
    def method(self) -> str:
        return self.mapping.method

    @property
    def resolution(self) -> tuple[int, int]:
        return int(self.background.shape[0]), int(self.background.shape[1])

    # -- run time ------------------------------------------------------------------------

    def difference(self, images: np.ndarray) -> np.ndarray:
        """Colour difference to the background (float32 DN), blurred and clipped as calibrated;
        on a marker gel divided by the dots' transmission (`dots`)."""
        dots = None if self.markers is None else self.dots(images)
        return colour_difference(images, self.background, self.blur_px, self.colour_limit_dn,
                                 dots)

    def dots(self, images: np.ndarray) -> DotCorrection:
        """How the dots of frames on a marker gel come out of the colour difference
        (`markers.dot_correction`: gain and offset, still dots divided out and moved ones
        followed, and the pixels to fill in the gradients where that cannot be done: a dot's
        darkest core, a dot that moved and cannot be followed)."""
        assert self.markers is not None
        cached = self.__dict__.get("_dots")
        if cached is None:  # the background's: found once
            cached = self.__dict__["_dots"] = background_dots(self.background, self.markers)
        return dot_correction(images, self.markers, self.background, *cached)

    def gradients(self, images: np.ndarray) -> np.ndarray:
        """(p, q) = (dz/dx, dz/dy) as (..., H, W, 2) float32 for RGB images (..., H, W, 3).

        f(diff, x, y) - f(0, x, y): a pixel whose (blurred) difference is zero gets exactly 0.
        """
        images = np.asarray(images)
        self._check_shape(images.shape)
        if self.markers is None:
            return self.mapping.relative(self.difference(images), self.zero_map)
        dots = self.dots(images)
        diff = colour_difference(images, self.background, self.blur_px, self.colour_limit_dn,
                                 dots)
        return fill_gradients(self.mapping.relative(diff, self.zero_map), dots.fill)

    def gradients_torch(self, images: Any) -> Any:
        """The same on a torch tensor (..., H, W, 3) of RGB values, on the tensor's device."""
        import torch

        self._check_shape(tuple(images.shape))
        dev = images.device
        cache = self.__dict__.setdefault("_torch", {})
        if str(dev) not in cache:
            cache[str(dev)] = (torch.from_numpy(self.background.astype(np.float32)).to(dev),
                               torch.from_numpy(self.zero_map).to(dev))
        bg, zero = cache[str(dev)]
        diff = images.to(torch.float32) - bg
        fill = weight = None
        if self.markers is not None:  # the dots are found on the CPU
            dots = self.dots(images.cpu().numpy())
            fill = dots.fill
            diff = diff * torch.from_numpy(np.array(dots.gain, np.float32)).to(dev)
            if dots.offset is not None:
                diff = diff + torch.from_numpy(dots.offset).to(dev)
            if dots.blur_weight is not None:
                weight = torch.from_numpy(dots.blur_weight).to(dev)
        sharp = _blur_torch(diff, self.blur_px) if self.blur_px > 0 else diff
        if weight is not None:  # as markers.blur_difference
            sharp = (_blur_torch(diff, self.markers.dot_blur_px) - sharp) * weight + sharp
        diff = sharp
        diff = diff.clamp(-self.colour_limit_dn, self.colour_limit_dn)
        g = self.mapping.predict_torch(diff) - zero
        g = torch.where((diff != 0).any(dim=-1, keepdim=True), g, torch.zeros_like(g))
        if fill is not None:  # and filled on the CPU
            g = torch.from_numpy(fill_gradients(g.cpu().numpy(), fill)).to(dev)
        return g

    def _check_shape(self, shape: tuple[int, ...]) -> None:
        if len(shape) < 3 or shape[-1] != 3:
            raise VtsError(f"expected RGB images of shape (..., H, W, 3), got {tuple(shape)}")
        h, w = shape[-3], shape[-2]
        if (h, w) != self.resolution:
            raise VtsError(f"images are {h}x{w} but the calibration is for "
                           f"{self.resolution[0]}x{self.resolution[1]} (sensor {self.sensor})")

    # -- file ----------------------------------------------------------------------------

    def metadata(self) -> dict[str, Any]:
        """The JSON document stored in the file (schemas/calibration.schema.json)."""
        return {
            "format": FORMAT,
            "format_version": self.format_version,
            "sensor": self.sensor,
            "resolution": list(self.resolution),
            "mm_per_px": [float(self.mm_per_px[0]), float(self.mm_per_px[1])],
            "ball_radius_mm": float(self.ball_radius_mm),
            "method": self.method,
            "params": self.mapping.params,
            "features": {"colour": "RGB difference to the background, DN",
                         "position": "x, y of the pixel centre normalised to [-1, 1]",
                         "blur_px": float(self.blur_px),
                         "colour_limit_dn": float(self.colour_limit_dn),
                         **({} if self.markers is None
                            else {"markers": self.markers.to_dict()})},
            "rim": self.rim.to_dict(),
            "fit": self.fit,
            "n_presses": int(self.n_presses),
            "vtsbench_version": self.vtsbench_version,
            "created_by": self.created_by,
        }

    def tensors(self) -> dict[str, np.ndarray]:
        t = {k: np.ascontiguousarray(v) for k, v in self.mapping.arrays.items()}
        t["background"] = np.ascontiguousarray(self.background, np.uint8)
        t["zero_map"] = np.ascontiguousarray(self.zero_map, np.float32)
        return t


def colour_difference(images: np.ndarray, background: np.ndarray, blur_px: float,
                      limit_dn: float = 255.0, dots: DotCorrection | None = None) -> np.ndarray:
    """images - background in float32 DN, with a marker gel's dots taken out when given
    (`Calibration.dots`), Gaussian-blurred by blur_px (on the dots by their own blur,
    `DotCorrection.wide_px`), clipped to +-limit_dn."""
    diff = np.asarray(images, np.float32) - background.astype(np.float32)
    weight, wide_px = None, 0.0
    if dots is not None:  # divided out, then blurred wider over the dots
        dots.apply(diff)
        weight, wide_px = dots.blur_weight, dots.wide_px
    if blur_px > 0 or weight is not None:
        frames = diff.reshape(-1, *diff.shape[-3:])
        for k in range(frames.shape[0]):
            frames[k] = blur_difference(frames[k], blur_px, weight, wide_px)
    np.clip(diff, -limit_dn, limit_dn, out=diff)
    return diff


def _blur_torch(diff: Any, sigma: float) -> Any:
    """Separable Gaussian blur over H, W of (..., H, W, 3), reflecting at the border (as cv2)."""
    import torch

    radius = max(1, math.ceil(4 * sigma))
    x = torch.arange(-radius, radius + 1, dtype=torch.float32, device=diff.device)
    k = torch.exp(-(x**2) / (2 * sigma**2))
    k = k / k.sum()
    lead = diff.shape[:-3]
    h, w = diff.shape[-3:-1]
    t = diff.reshape(-1, h, w, 3).permute(0, 3, 1, 2).reshape(-1, 1, h, w)
    t = torch.nn.functional.pad(t, (radius, radius, 0, 0), mode="reflect")
    t = torch.nn.functional.conv2d(t, k.view(1, 1, 1, -1))
    t = torch.nn.functional.pad(t, (0, 0, radius, radius), mode="reflect")
    t = torch.nn.functional.conv2d(t, k.view(1, 1, -1, 1))
    return t.reshape(-1, 3, h, w).permute(0, 2, 3, 1).reshape(*lead, h, w, 3)


# -- saving and loading ----------------------------------------------------------------------


def save_calibration(cal: Calibration, path: str | Path) -> Path:
    """Write the calibration atomically as safetensors with its JSON metadata."""
    from safetensors.numpy import save

    from ..atomic import write_bytes_atomic

    path = Path(path)
    if path.parent and not path.parent.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
    meta = json.dumps(cal.metadata(), sort_keys=True, allow_nan=False)
    write_bytes_atomic(path, save(cal.tensors(), metadata={META_KEY: meta}))
    mask = os.umask(0)
    os.umask(mask)
    os.chmod(path, 0o666 & ~mask)  # the temporary file was private; readable like any file
    return path


def _header(data: bytes, path: Path) -> dict[str, Any]:
    """The safetensors JSON header, or a one-line error for anything else."""
    if len(data) < 8:
        raise VtsError("not a vtsbench calibration file (too short to be safetensors)", path)
    (n,) = struct.unpack("<Q", data[:8])
    if n == 0 or n > len(data) - 8:
        if 0 < n < 100_000_000 and data[8:9] == b"{":
            raise VtsError(f"truncated calibration file ({len(data)} bytes, its header alone "
                           f"promises {8 + n})", path)
        raise VtsError("not a vtsbench calibration file (no safetensors header)", path)
    from ..jsonio import loads

    head = loads(data[8:8 + n], path, "safetensors header")
    if not isinstance(head, dict):
        raise VtsError("not a vtsbench calibration file (unreadable safetensors header)", path)
    end = max((int(v["data_offsets"][1]) for k, v in head.items()
               if k != "__metadata__" and isinstance(v, dict) and "data_offsets" in v),
              default=0)
    if 8 + n + end > len(data):
        raise VtsError(f"truncated calibration file ({len(data)} bytes, the header promises "
                       f"{8 + n + end})", path)
    return head


def metadata_errors(meta: Any) -> list[str]:
    """Every violation of the calibration metadata schema, one line each."""

    schema = json.loads(SCHEMA_PATH.read_text())
    from ..jsonio import strict_validator

    v = strict_validator(schema)
    out = []
    for err in sorted(v.iter_errors(meta), key=lambda e: list(map(str, e.absolute_path))):
        where = ".".join(map(str, err.absolute_path)) or "(top level)"
        out.append(f"{where}: {err.message}")
    return out


def load_calibration(path: str | Path, *, sensor: str | None = None,
                     resolution: tuple[int, int] | None = None) -> Calibration:
    """Read a calibration file; one-line VtsError for anything that is not a usable one.

    sensor, resolution: what the caller expects; a calibration of another sensor or resolution
    is refused, naming both.
    """
    from safetensors.numpy import load

    path = Path(path)
    if not path.is_file():
        raise VtsError("calibration file not found", path)
    from ..jsonio import loads, read_bytes

    data = read_bytes(path, "calibration file")
    head = _header(data, path)
    raw = (head.get("__metadata__") or {}).get(META_KEY)
    if raw is None:
        raise VtsError("not a vtsbench calibration file (safetensors without vtsbench metadata)",
                       path)
    meta = loads(raw, path, "calibration metadata") if isinstance(raw, str) else raw
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise VtsError(f"not a vtsbench calibration file (format {meta.get('format')!r})"
                       if isinstance(meta, dict) else "not a vtsbench calibration file", path)
    ver = str(meta.get("format_version", ""))
    if ver.split(".")[0] != FORMAT_VERSION.split(".")[0]:
        raise VtsError(f"calibration format version {ver!r} is not supported (this vtsbench "
                       f"reads {FORMAT_VERSION.split('.')[0]}.x); calibrate again", path)
    errs = metadata_errors(meta)
    if errs:
        more = f" (and {len(errs) - 1} more)" if len(errs) > 1 else ""
        raise VtsError(f"corrupt calibration metadata: {errs[0]}{more}", path)
    res = (int(meta["resolution"][0]), int(meta["resolution"][1]))
    if sensor is not None and meta["sensor"] != sensor:
        raise VtsError(f"calibration is for sensor {meta['sensor']!r}, expected {sensor!r}", path)
    if resolution is not None and tuple(int(v) for v in resolution) != res:
        raise VtsError(f"calibration is for {res[0]}x{res[1]} frames, expected "
                       f"{int(resolution[0])}x{int(resolution[1])}", path)
    try:
        tensors = load(data)
    except Exception as e:  # safetensors raises its own error type for damaged data
        raise VtsError(f"corrupt calibration file ({str(e).splitlines()[0]})", path) from None
    for name, arr in tensors.items():  # a NaN coefficient would turn every depth into zeros
        if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
            raise VtsError(f"corrupt calibration file (tensor {name!r} holds NaN or infinity)",
                           path)
    bg, zero = tensors.pop("background", None), tensors.pop("zero_map", None)
    if bg is None or bg.dtype != np.uint8 or bg.shape != (*res, 3):
        raise VtsError(f"corrupt calibration file (background missing or not {res[0]}x{res[1]}"
                       "x3 uint8)", path)
    if zero is None or zero.shape != (*res, 2):
        raise VtsError("corrupt calibration file (zero map missing or of the wrong shape)", path)
    try:
        mapping = mapping_from_arrays(meta["method"], meta["params"], tensors)
    except (KeyError, TypeError, ValueError) as e:
        raise VtsError(f"corrupt calibration file ({meta['method']} mapping: {e})", path) from None
    feats = meta["features"]
    return Calibration(
        mapping=mapping, background=bg, zero_map=zero.astype(np.float32), sensor=meta["sensor"],
        mm_per_px=(float(meta["mm_per_px"][0]), float(meta["mm_per_px"][1])),
        ball_radius_mm=float(meta["ball_radius_mm"]), rim=Rim.from_dict(meta["rim"]),
        blur_px=float(feats["blur_px"]), colour_limit_dn=float(feats["colour_limit_dn"]),
        markers=_marker_spec(feats.get("markers"), path),
        fit=meta["fit"], n_presses=int(meta["n_presses"]), created_by=meta["created_by"],
        vtsbench_version=meta["vtsbench_version"], format_version=ver)


#: The largest dots' own blur (px) a calibration file may ask for.
MAX_DOT_BLUR_PX = 64.0


def _marker_spec(d: Any, path: Path) -> MarkerSpec | None:
    """The stored marker settings, or None; a one-line error when they are damaged."""
    if d is None:
        return None
    try:
        spec = MarkerSpec.from_dict(d)
    except (KeyError, TypeError, ValueError) as e:
        raise VtsError(f"corrupt calibration metadata: features.markers ({e})", path) from None
    # the dots' own blur: a Gaussian of that size per frame, so bounded (a dot is under 3 mm)
    if not (spec.diameter_px > 0 and spec.window_px >= 3 and spec.window_px % 2 == 1
            and 0 < spec.contrast < 1 and spec.grow_px >= 0
            and 0 <= spec.dot_blur_px <= MAX_DOT_BLUR_PX):
        raise VtsError("corrupt calibration metadata: features.markers out of range", path)
    return spec


# -- calibrating -----------------------------------------------------------------------------


@dataclass
class Press:
    """One usable press: its frame, circle and where the circle came from."""

    id: str
    image: np.ndarray  # (H, W, 3) uint8
    x: float
    y: float
    r: float
    ball_radius_mm: float
    circle_source: str  # "label" or "detected"
    truth: Path | None = None


@dataclass
class HeldOut:
    """A held-out press: its errors and the maps the report draws."""

    press: Press
    errors: dict[str, float]
    reference: str  # "truth" (simulated ground truth) or "sphere" (the sphere model)
    true_depth: np.ndarray
    pred_depth: np.ndarray
    region: np.ndarray
    held_out: bool = True
    #: The errors and artefacts of every solver (dct, dst, masked) on this press.
    by_solver: dict[str, dict[str, float]] = field(default_factory=dict)


@dataclass
class CalibrationRun:
    """What `calibrate` returns: the calibration, its held-out presses and what happened."""

    calibration: Calibration
    held_out: list[HeldOut]
    warnings: list[str]
    seconds: float
    train_examples: list[HeldOut] = field(default_factory=list)
    #: Per press: the circle used (labelled or detected), the other one, status and reasons.
    presses: list[dict[str, Any]] = field(default_factory=list)
    #: Every press frame by id, used or dropped (the report's contact sheet draws them).
    frames: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    #: What is wrong with the background, if anything, or with the light of some presses
    #: against it (also among the warnings; the contact sheet shows it under its title).
    background_notes: list[str] = field(default_factory=list)

    @property
    def dropped(self) -> list[str]:
        return [p["id"] for p in self.presses if p["status"] == "dropped"]

    @property
    def doubted(self) -> list[str]:
        return [p["id"] for p in self.presses if p["status"] == "doubted"]

    @property
    def retried(self) -> list[str]:
        """Presses whose first detected circle failed its check and was detected again (from
        the imprint, or against presses of their own light)."""
        return [p["id"] for p in self.presses
                if p.get("retried_after") or p.get("against_background")]

    @property
    def shown(self) -> list[HeldOut]:
        """The presses a report shows: the held-out ones, else a few training presses."""
        return self.held_out or self.train_examples


#: Colour subsampling that costs a marker gel's depth no more than full colour does (4:2:2, half
#: the colour across only: 1.11-1.15x on the simulated gels at JPEG 75, as 4:4:4; docs/depth.md).
HARMLESS_SUBSAMPLING = frozenset({"4:2:2"})


def subsampled_colour_note(sources: dict[str, Path]) -> str | None:
    """A warning when a marker gel's press files store colour at a lower resolution than
    brightness both ways (`media.chroma_subsampling`: JPEG 4:2:0, most video codecs): a dark
    dot's colour then spreads over the codec's 16 px blocks, which the dot correction cannot
    take out (docs/depth.md, simulated marker gels: 1.22-1.29x the depth RMSE of the same
    presses without dots at JPEG quality 75 4:2:0, 1.11-1.15x at 4:2:2 and 4:4:4); None when
    none does."""
    from ..recordings.media import chroma_subsampling

    paths = sorted(set(sources.values()))
    found = [(p, k) for p in paths
             if (k := chroma_subsampling(p)) is not None and k not in HARMLESS_SUBSAMPLING]
    if not found:
        return None
    kinds = ", ".join(sorted({k for _, k in found}))
    return (f"marker gel recorded with {kinds} colour ({len(found)} of {len(paths)} press "
            f"files, e.g. {found[0][0].name}): the dots' colour spreads over the codec's "
            "blocks and costs depth accuracy (simulated gels at JPEG 75: 1.22-1.29x the error "
            "without dots, 1.11-1.15x at 4:2:2 or 4:4:4); record PNG, or JPEG 4:4:4 or 4:2:2 "
            "where the camera allows")


def _press_frame(root: Path, e: Any) -> np.ndarray:
    from ..recordings.media import read_frame

    return read_frame(root / e.source.path, e.source.frame or 0)


def _a_diameter(r_px: float, ball_px: float) -> bool:
    """A circle radius too large for the ball that halved would fit it (a diameter given)."""
    return RADIUS_TOLERANCE * ball_px < r_px <= 2 * RADIUS_TOLERANCE * ball_px


def check_scale(scale: tuple[float, float], ball_radius_mm: float, shape: tuple[int, int],
                radii_px: list[float], given: bool) -> None:
    """Refuse a scale that contradicts the ball and the image or the labelled circles, with one
    line; a value that looks like px/mm (above 1 mm/px, its inverse plausible) gets the hint."""
    what = f"--mm-per-px {scale[0]:g}" if given else f"mm_per_px {scale[0]:g} of the recordings"
    ball = ball_radius_px(ball_radius_mm, scale)
    h, w = shape
    why = None
    if ball < 2.0:
        why = (f"makes the {ball_radius_mm:g} mm ball {ball:.2g} px in radius: too small to "
               "press a visible contact")
    elif ball > math.hypot(h, w):
        why = f"makes the {ball_radius_mm:g} mm ball {ball:.0f} px in radius, beyond the " \
              f"{h}x{w} image"
    elif radii_px and float(np.median(radii_px)) > RADIUS_TOLERANCE * ball:
        why = (f"makes the {ball_radius_mm:g} mm ball {ball:.1f} px in radius, but half the "
               f"labelled circles are larger than {float(np.median(radii_px)):g} px")
    elif radii_px and max(radii_px) < 0.1 * ball:
        why = (f"makes the {ball_radius_mm:g} mm ball {ball:.0f} px in radius, but no labelled "
               f"circle is larger than {max(radii_px):g} px")
    if why is None:
        return
    hint = ""
    inv = 1.0 / scale[0]
    if scale[0] > 1.0 and 2.0 <= ball_radius_mm / inv <= math.hypot(h, w):
        hint = f"; {scale[0]:g} looks like px per mm: did you mean --mm-per-px {inv:.5g}?"
    elif radii_px and _a_diameter(float(np.median(radii_px)), ball):
        hint = "; or are the labels' radii diameters? (halved, half of them fit the ball)"
    raise VtsError(f"{what} {why} (check the scale and the ball radius){hint}")


def _resolve_scale(sessions: list[Any], mm_per_px: float | None) -> tuple[float, float]:
    if mm_per_px is not None:
        if not (math.isfinite(mm_per_px) and mm_per_px > 0):
            raise VtsError(f"--mm-per-px must be positive, got {mm_per_px}")
        return float(mm_per_px), float(mm_per_px)
    scales = {s.mm_per_px for s in sessions}
    if None in scales:
        missing = ", ".join(s.id for s in sessions if s.mm_per_px is None)
        raise VtsError(f"no mm_per_px for session {missing}: the scale is needed to turn the "
                       "ball radius into pixels; pass --mm-per-px")
    if len(scales) > 1:
        raise VtsError(f"the press sessions disagree on mm_per_px ({sorted(scales)}); "
                       "pass --mm-per-px")
    return scales.pop()


def _resolve_background(root: Path, sessions: list[Any], frames: list[np.ndarray],
                        background: Path | None, estimate: bool,
                        shape: tuple[int, int]) -> tuple[np.ndarray, str]:
    from ..recordings.media import read_frame, read_image

    if background is not None and estimate:
        raise VtsError("pass either --background FILE or --estimate-background, not both")
    if background is not None:
        bg, how = read_image(Path(background)), f"file {background}"
    elif estimate:
        if len(frames) < 3:
            raise VtsError(f"--estimate-background needs at least 3 press frames, got "
                           f"{len(frames)}")
        from .background import press_median

        bg, how = press_median(frames), f"median of {len(frames)} press frames"
    else:
        have = [s for s in sessions if s.background]
        if not have:
            raise VtsError("no background (no-contact frame) for the presses: pass --background "
                           "FILE or --estimate-background (the per-pixel median of the press "
                           "frames)")
        bgs = [read_frame(root / s.background, s.background_frame or 0) for s in have]
        bg = bgs[0] if len(bgs) == 1 else \
            np.median(np.stack(bgs), axis=0).round().astype(np.uint8)
        how = "session background" if len(bgs) == 1 else f"median of {len(bgs)} session " \
            "backgrounds"
    if bg.shape[:2] != shape:
        raise VtsError(f"background is {bg.shape[0]}x{bg.shape[1]} but the presses are "
                       f"{shape[0]}x{shape[1]}", background)
    return bg, how


def _background_warnings(bg: np.ndarray, how: str, frames: list[np.ndarray],
                         ball_px: float) -> list[str]:
    """Warnings about a given background held against the presses' median: its colour
    channels in the other order (`background.channels_reversed`), or a contact the presses do
    not show (`background.own_contact`: a press frame given as the background)."""
    from .background import MIN_FRAMES, channels_reversed, own_contact, press_median

    if len(frames) < MIN_FRAMES:
        return []
    med = press_median(frames)
    rev = channels_reversed(bg, med)
    if rev is not None:
        return [f"the background ({how}) has its colour channels in the other order from the "
                f"presses' (it lies {rev[0]:.0f} DN from their median, {rev[1]:.0f} DN with its "
                "channels reversed): was it saved as BGR where RGB was meant, or the other way? "
                "Save it as the presses are saved"]
    c = own_contact(bg, frames, ball_px, med)
    if c is None:
        return []
    return [f"the background ({how}) shows a contact of its own at ({c[0]:.0f}, {c[1]:.0f}) "
            f"r {c[2]:.0f} px that the presses do not: is it a press frame? Every press is "
            "measured against it, and circles are found there instead of at their own contact; "
            "pass a frame of the untouched gel, or --estimate-background"]


#: Labelled circles read another way, for `_label_layout_hint`: (x, y, r) of a circle in a frame
#: of (h, w) as the labels would give it had they been written in that layout.
Layout = Callable[[float, float, float, int, int], tuple[float, float, float]]
LABEL_LAYOUTS: dict[str, Layout] = {
    "with x and y swapped (as row, column)": lambda x, y, r, h, w: (y, x, r),
    "mirrored left to right": lambda x, y, r, h, w: (w - 1 - x, y, r),
    "upside down (rows counted from the bottom)": lambda x, y, r, h, w: (x, h - 1 - y, r),
    "turned half a turn": lambda x, y, r, h, w: (w - 1 - x, h - 1 - y, r),
    "as pixels of a frame twice the size": lambda x, y, r, h, w: (
        (x + 0.5) / 2 - 0.5, (y + 0.5) / 2 - 0.5, r / 2),
    "as pixels of a frame half the size": lambda x, y, r, h, w: (
        (x + 0.5) * 2 - 0.5, (y + 0.5) * 2 - 0.5, r * 2),
}
#: The hint is given when at least this share of the labelled presses (and 3) are doubted, and
#: another layout lets LAYOUT_PASS of them pass the check, 3 more than pass as written. (A large
#: contact in a small frame can still cover much of a swapped circle: on 10 simulated presses of
#: 18-34 px in 120x160 frames, swapping x and y left 6 passing.)
LABELS_DOUBTED, LAYOUT_PASS = 0.3, 0.8


def _label_layout_hint(record: list[dict[str, Any]], frames: dict[str, np.ndarray],
                       bg: np.ndarray, shape: tuple[int, int], ball_px: float) -> list[str]:
    """A warning when many labelled circles are doubted (LABELS_DOUBTED) and the labels read in
    another layout (`LABEL_LAYOUTS`: x and y swapped, mirrored, upside down, another frame
    size) would pass the check: labels written as (row, column), or in a flipped or resized
    frame's pixels. Each press's change map is built once for all the layouts."""
    from .sphere import change_map, default_sigma

    rows = [r for r in record if r["source"] == "label" and r["label"]]
    doubted = [r for r in rows if r["status"] == "doubted"]
    if ball_px <= 0 or len(doubted) < max(3, LABELS_DOUBTED * len(rows)):
        return []
    h, w = shape
    maps = {r["id"]: change_map(frames[r["id"]], bg, default_sigma(shape), markers=True)
            for r in rows}
    for name, move in LABEL_LAYOUTS.items():
        passed = sum(not circle_doubts(move(*_xyr(r["label"]), h, w), frames[r["id"]], bg,
                                       ball_px, maps[r["id"]])
                     for r in rows)
        if passed >= max(LAYOUT_PASS * len(rows), len(rows) - len(doubted) + 3):
            return [f"{len(doubted)} of {len(rows)} labelled circles do not fit their presses' "
                    f"colour change; read {name}, {passed} of them do: were the labels written "
                    "that way? Fix the labels (or the manifest's circles), or run --circles "
                    "detect"]
    return []


def _crowded_warning(shape: tuple[int, int], presses: list[Press], n_frames: int) -> list[str]:
    """A warning when half or more of the presses the background was estimated from touch one
    spot: the median there is a press (`background.crowded`)."""
    from .background import crowded

    spot = crowded(shape, [(p.x, p.y, p.r) for p in presses], n_frames)
    if spot is None:
        return []
    n, (x, y) = spot
    return [f"the background was estimated from the presses, but {n} of {n_frames} touch "
            f"({x}, {y}) px: the median there is a press, so their colour change is measured "
            "against a press and the mapping learns from it; record a no-contact frame and pass "
            "--background FILE, or spread the presses so that fewer than half touch any spot"]


def _retry_detection(img: np.ndarray, bg: np.ndarray, ball_px: float,
                     first: tuple[float, float, float]) -> tuple[float, float, float] | None:
    """A second detection started from the changed region's centre and size; when that fails
    too and the first circle was smaller than the check allows, a whole detection again among
    the radii the check allows (`sphere.SUPPORT_LOW` of the change's). Kept only when it passes
    the check that the first one failed."""
    from .imprint import ring_contrast
    from .sphere import RING_Z_MIN, SUPPORT_LOW, change_map, change_support, default_sigma

    m = change_map(img, bg, default_sigma(img.shape[:2]), markers=True)  # built once, used 4x
    sup = change_support(img, bg, m=m)
    if sup is None:
        return None
    found = detect_circle(img, bg, start=(sup[0], sup[1], 0.8 * sup[2]), ball_px=ball_px)
    if found is not None and not circle_doubts(found, img, bg, ball_px, m):
        return found
    if first[2] >= SUPPORT_LOW * sup[2]:
        return None
    # a small strong feature inside a faint imprint (a monochrome camera: one dark crescent
    # of the contact stands out of its ring) won the first detection
    found = detect_circle(img, bg, ball_px=ball_px, min_radius_px=SUPPORT_LOW * sup[2])
    if found is None or circle_doubts(found, img, bg, ball_px, m) or ring_contrast(
            m, found) < RING_Z_MIN:
        # and only a circle whose rim stands out (DIGIT 0008 cut by the border, moved markers
        # and JPEG: a circle 12 px off its contact passed the check with a rim contrast of 2.3;
        # Taxim's press-002 in grey, found, 11.7)
        return None
    return found


def _detect_against_mates(record: list[dict[str, Any]], frames: dict[str, np.ndarray],
                          bg: np.ndarray, balls: dict[str, float],
                          notes: dict[str, list[str]]) -> list[str]:
    """Detected circles of presses taken under another light than the background, checked (and
    found when missing) against presses of their own light; a warning naming those presses.

    Such a press shows that light's change over the whole gel (DIGIT 0016 and 0017), where its
    contact can drown (rotated, 2.5 times the size, with moved markers and JPEG; or in grey)
    and noise can pass for one (a simulated frame without contact under another layout passed
    the check). The presses that share its light (`background.light_mates`) stand in for the
    background, each with its own contact left out (`background.mates_background`; a contact
    not known is outvoted by three mates or more, and left out with fewer). A circle holds when
    it passes the check against them, its rim stands out (`sphere.RING_Z_MIN`), and less than
    half of it lies where no mate was free (filled in). A detected circle that does not hold
    is no longer trusted (its contact counts as not known); its press is detected again against
    the mates, and dropped when that fails too. Labelled circles are not touched."""
    from .background import light_mates, mates_background, share_filled
    from .imprint import ring_contrast
    from .sphere import RING_Z_MIN, change_map, default_sigma

    groups = light_mates(frames, bg)
    if not groups:
        return []
    rows = {r["id"]: r for r in record}
    # each press's circle as far as it is trusted (labels, and detected circles that hold);
    # None where its contact is not known
    trusted: dict[str, tuple[float, float, float] | None] = {
        k: None if r["status"] == "dropped" else _xyr(r["circle"]) for k, r in rows.items()}

    def mates_of(pid: str) -> list[str]:
        """The presses that make its background: all of its light, or with fewer than three
        (too few to outvote a contact whose circle is not known) those with a known contact."""
        mates = groups[pid]
        return mates if len(mates) >= 3 else [k for k in mates if trusted[k] is not None]

    made: dict[str, Any] = {}  # each press's last test, kept while its mates' circles stand

    def against(pid: str) -> Any:
        """That background, and a test of a circle against it (None when there is nothing to
        hold it against)."""
        mates = mates_of(pid)
        key = tuple((k, trusted[k]) for k in mates)
        if pid not in made or made[pid][0] != key:
            made[pid] = key, _mates_test(pid, mates) if mates else None
        return made[pid][1]

    def _mates_test(pid: str, mates: list[str]) -> Any:
        img, ball = frames[pid], balls[pid]
        ref, filled = mates_background([frames[k] for k in mates],
                                       [trusted[k] for k in mates], bg)
        m = change_map(img, ref, default_sigma(img.shape[:2]), markers=True)

        def holds(c: tuple[float, float, float] | None) -> bool:
            return c is not None and not circle_doubts(c, img, ref, ball, m) and share_filled(
                c, filled) < 0.5 and ring_contrast(m, c) >= RING_Z_MIN

        return ref, holds

    checked = [k for k in groups if rows[k]["source"] == "detected"]
    found: dict[str, tuple[float, float, float]] = {}  # circles found against the mates
    failed: set[str] = set()  # failed a check against mates: not detected there again

    def verify() -> bool:
        """Each trusted detected circle against the others as they stand; False if none
        failed."""
        out = [k for k in checked if trusted[k] is not None and (t := against(k))
               and not t[1](trusted[k])]
        for k in out:
            trusted[k] = None
        failed.update(k for k in out if k in found)
        return bool(out)

    for _ in range(4):  # until nothing changes: circles that fail leave, contacts found join
        changed = verify()
        for k in checked:
            if trusted[k] is not None or k in failed:
                continue
            test = against(k)
            c = None if test is None else detect_circle(frames[k], test[0], ball_px=balls[k])
            if test is not None and test[1](c):
                trusted[k] = found[k] = c
                changed = True
        if not changed:
            break
    else:
        verify()  # the rounds ran out while still changing: the last word is the check
    for pid in checked:
        row, c = rows[pid], trusted[pid]
        mates = mates_of(pid)
        who = f"press{'es' if len(mates) > 1 else ''} {', '.join(mates)}"
        if c is None:
            if row["status"] != "dropped" and mates:
                row.update(status="dropped", against_presses=mates, reasons=[
                    f"its circle does not show against {who} of its own light, nor another"])
            continue
        if pid not in found:
            continue  # its circle against the background holds against the mates too
        was = "; ".join(row["reasons"]) if row["status"] == "dropped" else \
            "its circle does not show against them"
        row.update(status="used", reasons=[], against_presses=mates, against_background=was,
                   first_detected=row["detected"], detected=_circle(c), circle=_circle(c))
        if row["label"] is not None:
            row.update(label_agreement(_xyr(row["label"]), c, balls[pid]))
        notes[pid].append(f"press {pid}: against the background, {was}; against {who} of its "
                          f"light (contacts left out) it shows ({c[0]:.1f}, {c[1]:.1f}) r "
                          f"{c[2]:.1f} px")
    ids = sorted(groups)
    return [f"press{'es' if len(ids) > 1 else ''} {', '.join(ids)} lie far from the background "
            "and near one another: taken under another light or exposure? Their detected "
            "circles are checked against one another (contacts left out), but the mapping "
            "learns their change from the background, light and all; record a background "
            "under each light and calibrate each light's presses apart"]


def _circle(c: tuple[float, float, float] | None) -> dict[str, float | None] | None:
    return None if c is None else {"x": _num(c[0]), "y": _num(c[1]), "r": _num(c[2])}


def _xyr(c: dict[str, Any]) -> tuple[float, float, float]:
    """A record's circle (`_circle`'s dict) as (x, y, r)."""
    return c["x"], c["y"], c["r"]


def label_agreement(label: tuple[float, float, float], found: tuple[float, float, float],
                    ball_px: float) -> dict[str, float]:
    """How far a detected circle lies from its label: the centres' distance (px) and the
    radius error with both radii clamped below the ball as the fit clamps them (`Rim`)."""
    top = Rim().max_radius_frac * ball_px
    return {"label_offset_px": float(math.hypot(found[0] - label[0], found[1] - label[1])),
            "label_radius_error": float(min(found[2], top) / min(label[2], top) - 1)}


def load_presses(folder: str | Path, *, mm_per_px: float | None = None,
                 background: Path | None = None, estimate_background: bool = False,
                 circles: str = "label"
                 ) -> tuple[list[Press], np.ndarray, dict[str, Any], list[str]]:
    """The usable presses of a recordings folder, the background, the setup and warnings.

    circles: "label" uses labelled circles and detects the others; "detect" detects every
    circle (the labels are kept in the record for comparison). Every circle is checked
    (`sphere.circle_doubts`): an implausible detected circle drops its press, a doubted label is
    used with a warning; setup["presses"] records, per press, the circle used and why."""
    from ..recordings.manifest import load_manifest

    root = Path(folder)
    m = load_manifest(root)
    entries = [e for e in m.entries if e.kind == "press"]
    if not entries:
        raise VtsError("no press entries (calibration needs ball presses: entries of kind "
                       "'press', e.g. from `vtsbench collect --kind press`)", root)
    sessions = list({e.session: m.session(e.session) for e in entries}.values())
    sensors = sorted({s.sensor for s in sessions})
    if len(sensors) > 1:
        raise VtsError(f"presses from several sensors ({', '.join(sensors)}): a calibration is "
                       "per sensor; give it a folder with one sensor's presses", root)
    shapes = sorted({tuple(s.resolution) for s in sessions})
    if len(shapes) > 1:
        raise VtsError(f"press sessions of several resolutions ({shapes}); calibrate each "
                       "separately", root)
    shape = (int(shapes[0][0]), int(shapes[0][1]))
    scale = _resolve_scale(sessions, mm_per_px)
    balls = [float(e.ball_radius_mm) for e in entries if e.ball_radius_mm is not None]
    if balls:
        # each labelled circle against its own ball, as a circle on the smallest ball (gs_sdk
        # catalogs mix balls: a large ball's circles are not too large for the small one)
        small = min(balls)
        check_scale(scale, small, shape,
                    [e.circle.r * small / e.ball_radius_mm for e in entries
                     if e.circle is not None and e.ball_radius_mm], mm_per_px is not None)
    for e in entries:
        if e.ball_radius_mm is None:
            raise VtsError(f"press {e.id} has no ball radius (set ball_radius_mm in the "
                           "manifest, e.g. `vtsbench manifest ... --ball-radius-mm 3`)", root)
        d = e.labels.press_depth_mm
        if d is not None and d >= e.ball_radius_mm:
            raise VtsError(f"press {e.id} is {d} mm deep, not less than the ball radius "
                           f"{e.ball_radius_mm} mm", root)
        if e.circle is not None:
            r_ball = ball_radius_px(e.ball_radius_mm, scale)
            if e.circle.r > RADIUS_TOLERANCE * r_ball:
                half = " (or is it a diameter?)" if _a_diameter(e.circle.r, r_ball) else ""
                raise VtsError(f"press {e.id}: circle radius {e.circle.r:g} px is larger than "
                               f"the ball ({e.ball_radius_mm:g} mm = {r_ball:.1f} px at "
                               f"{scale[0]:g} mm/px); check the scale or the ball radius{half}",
                               root)
    frames = []
    for e in entries:
        img = _press_frame(root, e)
        if img.shape[:2] != shape:
            raise VtsError(f"press {e.id} is {img.shape[0]}x{img.shape[1]}, its session says "
                           f"{shape[0]}x{shape[1]}", root / e.source.path)
        frames.append(img)
    bg, bg_how = _resolve_background(root, sessions, frames, background, estimate_background,
                                     shape)
    presses, warnings, lost = [], [], []
    small_px = ball_radius_px(min(balls), scale) if balls else 0.0  # the smallest ball's radius
    by_id = {e.id: img for e, img in zip(entries, frames, strict=True)}
    bg_notes = [] if estimate_background or not balls else _background_warnings(
        bg, bg_how, frames, small_px)
    warnings.extend(bg_notes)
    record: list[dict[str, Any]] = []
    notes: dict[str, list[str]] = {}  # each press's warnings, in entry order at the end
    ball_px = {e.id: ball_radius_px(float(e.ball_radius_mm), scale) for e in entries}
    for e, img in zip(entries, frames, strict=True):
        ball = ball_px[e.id]
        label = None if e.circle is None else (e.circle.x, e.circle.y, e.circle.r)
        found = detect_circle(img, bg, ball_px=ball) if label is None or circles == "detect" \
            else None
        use, source = (label, "label") if label is not None and circles != "detect" \
            else (found, "detected")
        row: dict[str, Any] = {"id": e.id, "source": source, "label": _circle(label),
                               "detected": _circle(found), "circle": _circle(use)}
        notes[e.id] = []
        doubts = [] if use is None else circle_doubts(use, img, bg, ball)
        if source == "detected" and use is not None and doubts:
            # retry from the imprint as the colour change shows it (the strongest change can be
            # a small saturated patch beside the contact); a frame without contact is not
            # retried: the noise would give some circle
            again = _retry_detection(img, bg, ball, use)
            if again is not None:
                row.update(detected=_circle(again), circle=_circle(again),
                           retried_after=doubts, first_detected=_circle(use))
                notes[e.id].append(f"press {e.id}: first detected circle implausible "
                                   f"({'; '.join(doubts)}); detected again from the imprint: "
                                   f"({again[0]:.1f}, {again[1]:.1f}) r {again[2]:.1f} px")
                use, found, doubts = again, again, []
        if label is not None and found is not None:
            row.update(label_agreement(label, found, ball))
        if use is None:
            row.update(status="dropped", reasons=["no visible contact: no circle detected"])
        elif doubts and source == "detected":
            row.update(status="dropped", reasons=[f"implausible detected circle: {d}"
                                                  for d in doubts])
        else:
            row.update(status="doubted" if doubts else "used", reasons=doubts)
        record.append(row)
    light_notes = _detect_against_mates(record, by_id, bg, ball_px, notes)
    for e, img, row in zip(entries, frames, record, strict=True):
        warnings.extend(notes[e.id])
        if row["status"] == "dropped":
            lost.append(e.id)
            warnings.append(f"press {e.id} dropped: {'; '.join(row['reasons'])}")
            continue
        if row["status"] == "doubted":
            warnings.append(f"press {e.id}: labelled circle doubted "
                            f"({'; '.join(row['reasons'])}); used as labelled")
        presses.append(Press(e.id, img, *_xyr(row["circle"]), float(e.ball_radius_mm),
                             row["source"], root / e.truth if e.truth else None))
    warnings.extend(light_notes)
    if estimate_background:
        bg_notes = _crowded_warning(shape, presses, len(frames))
        warnings.extend(bg_notes)
    if circles != "detect":
        warnings.extend(_label_layout_hint(record, by_id, bg, shape, small_px))
    radii = sorted({p.ball_radius_mm for p in presses})
    setup = {"root": root, "sensor": sensors[0], "shape": shape, "mm_per_px": scale,
             "background": bg_how, "lost": lost, "n_entries": len(entries), "presses": record,
             "ball_radius_mm": radii[0] if radii else float(entries[0].ball_radius_mm),
             "frames": by_id,
             "background_notes": bg_notes + light_notes,
             "sources": {e.id: root / e.source.path for e in entries}}
    if len(radii) > 1:
        warnings.append(f"presses of several ball radii ({radii} mm); the file records "
                        f"{radii[0]} mm")
    return presses, bg, setup, warnings


def training_samples(presses: list[Press], background: np.ndarray, scale: tuple[float, float],
                     rim: Rim, blur_px: float, rng: np.random.Generator,
                     markers: MarkerSpec | None = None,
                     dots: tuple[np.ndarray, np.ndarray] | None = None
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(colour (N, 3), xy (N, 2), target (N, 2), is_cap (N,)) from the presses' labelled pixels;
    with markers, the colour difference is the run time's (the dots divided back, then
    blurred), and of the pixels the run time divides or fills the fit leaves out the dots'
    dark cores, where moved dots went and what is filled (`markers.left_out_of_fit`): divided
    back (`Calibration.dots`), a dot's pixels carry up to 1 / DOT_MIN_TRANSMISSION times the
    noise, which would bias the fit towards flat; it learns from the gel between the dots,
    their grown ring and their lighter parts (FIT_MIN_TRANSMISSION). A press's own dark blobs
    are not left out as such: one can be a dot merged with a dark lobe of the imprint, and
    without the lobe's colours the fit extrapolates (simulated `zones3`: a held-out press 21.4
    um off against 8.9 um). dots: the background's (transmission, grown dots)
    (`markers.background_dots`), found when not given."""
    from .mapping import norm_xy

    h, w = background.shape[:2]
    xn, yn = norm_xy(h, w)
    if markers is not None and dots is None:
        dots = background_dots(background, markers)
    trans, base = (None, None) if markers is None else dots
    cols, xys, tgts, caps = [], [], [], []
    for p in presses:
        f = sphere_fields((h, w), p.x, p.y, p.r, p.ball_radius_mm, scale, rim)
        corr = None if markers is None else dot_correction(p.image, markers, background, trans,
                                                           base)
        diff = colour_difference(p.image, background, blur_px, dots=corr)
        left_out = None if corr is None else left_out_of_fit(corr, trans)
        for sel, n_max, is_cap in ((f.trusted, CAP_SAMPLES, True), (f.flat, FLAT_SAMPLES, False)):
            if left_out is not None:
                sel = sel & ~left_out
            ys, xs = np.nonzero(sel)
            if ys.size > n_max:
                k = np.sort(rng.choice(ys.size, n_max, replace=False))
                ys, xs = ys[k], xs[k]
            cols.append(diff[ys, xs])
            xys.append(np.column_stack([xn[xs], yn[ys]]))
            tgts.append(np.column_stack([f.p[ys, xs], f.q[ys, xs]]) if is_cap
                        else np.zeros((ys.size, 2), np.float32))
            caps.append(np.full(ys.size, is_cap))
    return (np.concatenate(cols).astype(np.float32), np.concatenate(xys).astype(np.float32),
            np.concatenate(tgts).astype(np.float32), np.concatenate(caps))


def fit_calibration(train: list[Press], background: np.ndarray, setup: dict[str, Any],
                    method: str, *, rim: Rim, blur_px: float, rng: np.random.Generator,
                    options: dict[str, Any] | None = None, markers: str = "auto"
                    ) -> tuple[Calibration, tuple[np.ndarray, ...]]:
    """A calibration fitted to training presses (setup: `load_presses`'s), with its samples
    (colour, xy, target, is_cap): labels, colour clip, mapping and zero map.

    markers: "auto" finds a marker grid in the background (markers.detect_markers) and, when
    there is one, leaves the dots out of the samples and fills them at run time; "off" never."""
    scale = setup["mm_per_px"]
    if markers not in ("auto", "off"):
        raise VtsError(f"--markers must be auto or off, got {markers!r}")
    spec = detect_markers(background, scale, grow_px=max(1, math.ceil(2 * blur_px))) \
        if markers == "auto" else None
    if spec is not None:
        spec = replace(spec, dot_blur_px=dot_blur_px(scale, blur_px))
    dots = None if spec is None else background_dots(background, spec)
    colour, xy, target, is_cap = training_samples(train, background, scale, rim, blur_px, rng,
                                                  spec, dots)
    limit = float(min(255.0, np.percentile(np.abs(colour), 99.9) * 1.05 + 1.0))
    np.clip(colour, -limit, limit, out=colour)
    mapping = fit_mapping(method, colour, xy, target, **dict(options or {}))
    h, w = setup["shape"]
    zero = mapping.predict(np.zeros((h, w, 3), np.float32))
    cal = Calibration(mapping=mapping, background=background, zero_map=zero,
                      sensor=setup["sensor"], mm_per_px=scale,
                      ball_radius_mm=setup["ball_radius_mm"], rim=rim, blur_px=blur_px,
                      colour_limit_dn=limit, n_presses=len(train), markers=spec)
    if dots is not None:  # the run time's cache (`Calibration.dots`): found once
        cal.__dict__["_dots"] = dots
    return cal, (colour, xy, target, is_cap)


#: Rim shrink settings (shrink_px, shrink_frac) that `rim_cv` chooses among.
RIM_CANDIDATES = ((2.0, 0.06), (1.0, 0.03), (0.5, 0.03), (0.0, 0.0))


def choose_rim(train: list[Press], background: np.ndarray, setup: dict[str, Any], method: str,
               *, rim: Rim, blur_px: float, seed: int, options: dict[str, Any] | None = None,
               markers: str = "auto", folds: int = 4) -> tuple[Rim, dict[str, float]]:
    """The rim shrink (RIM_CANDIDATES, the rest of `rim` kept) with the lowest mean
    plane-aligned RMSE in `folds`-fold cross-validation over the training presses alone, and
    each candidate's score ("shrink_px/shrink_frac" -> mm)."""
    k = max(2, min(int(folds), len(train)))
    fold = np.arange(len(train)) % k
    scores: dict[str, float] = {}
    best: tuple[float, Rim] | None = None
    for px, frac in RIM_CANDIDATES:
        cand = replace(rim, shrink_px=px, shrink_frac=frac)
        errs = []
        for f in range(k):
            fit_on = [p for p, g in zip(train, fold, strict=True) if g != f]
            cal, _ = fit_calibration(fit_on, background, setup, method, rim=cand,
                                     blur_px=blur_px, rng=np.random.default_rng(seed),
                                     options=options, markers=markers)
            errs += [evaluate_press(cal, p).errors["plane_aligned_rmse_mm"]
                     for p, g in zip(train, fold, strict=True) if g == f]
        score = float(np.nanmean(errs))
        scores[f"{px:g}/{frac:g}"] = score
        if best is None or score < best[0]:
            best = (score, cand)
    assert best is not None
    return best[1], scores


def evaluate_press(cal: Calibration, press: Press, *, solver: str = "dct",
                   held_out: bool = True) -> HeldOut:
    """Errors of one press: gradient RMSE over the trusted cap, depth errors of its integral."""
    from ..recordings.truth import read_truth
    from .metrics import depth_errors
    from .poisson import integrate

    h, w = cal.resolution
    f = sphere_fields((h, w), press.x, press.y, press.r, press.ball_radius_mm, cal.mm_per_px,
                      cal.rim)
    g = cal.gradients(press.image)
    e = np.hypot(g[..., 0] - f.p, g[..., 1] - f.q)[f.trusted]
    grad_rmse = float(np.sqrt(np.mean(e**2))) if e.size else math.nan
    if press.truth is not None:
        t = read_truth(press.truth)
        true, region, ref = t.depth_mm[0], t.contact[0], "truth"
    else:
        true, region, ref = f.depth_mm, f.contact, "sphere"
    preds, by_solver = {}, {}
    for s in SOLVERS:
        # masked: zero outside the press's contact, as the paper integrates
        preds[s] = integrate(g[..., 0], g[..., 1], method=s, mm_per_px=cal.mm_per_px,
                             mask=region if s == "masked" else None)
        by_solver[s] = {**depth_errors(preds[s], true, region).to_dict(),
                        **artefacts(preds[s])}
    errs = {"gradient_rmse": grad_rmse, **by_solver[solver]}
    return HeldOut(press, errs, ref, true, preds[solver], region, held_out, by_solver)


#: Width (px) of the frame border whose mean |depth| measures border streaks.
BORDER_PX = 2


def artefacts(depth: np.ndarray) -> dict[str, float]:
    """Negative depth (the lowest value, mm; and the share of pixels below -0.02 mm) and border
    streaks (mean |depth| over the outermost BORDER_PX pixels, mm) of one depth map."""
    b = BORDER_PX
    edge = np.concatenate([depth[:b].ravel(), depth[-b:].ravel(), depth[b:-b, :b].ravel(),
                           depth[b:-b, -b:].ravel()])
    return {"min_depth_mm": float(depth.min()),
            "negative_share": float((depth < -0.02).mean()),
            "border_abs_mm": float(np.abs(edge).mean())}


def calibrate(folder: str | Path, *, method: str = "mlp", holdout: int | None = None,
              seed: int = 0, mm_per_px: float | None = None, background: Path | None = None,
              estimate_background: bool = False, rim: Rim | None = None,
              blur_px: float = BLUR_PX, solver: str = "dct", device: str | None = "auto",
              options: dict[str, Any] | None = None,
              log: Callable[[str], None] | None = None, circles: str = "label",
              markers: str = "auto", rim_cv: bool = False) -> CalibrationRun:
    """Fit a calibration from the presses of a recordings folder (see the module doc).

    holdout: presses kept out of training and scored (default: a fifth, none below 4 presses).
    options: the method's parameters (lut: bins, cells; poly: degree; mlp: width, depth,
    epochs, lr, batch_size). markers: "auto" (a marker grid found in the background is left
    out of the fit and filled before integration, see markers.py) or "off". rim_cv: choose
    the rim shrink by cross-validation over the training presses (`choose_rim`; the held-out
    presses take no part), at 4 x 4 extra fits.
    """
    t0 = time.perf_counter()
    say = log or (lambda _msg: None)
    if method not in METHODS:
        raise VtsError(f"unknown method {method!r} (use one of {', '.join(METHODS)})")
    rim = rim or Rim()
    if circles not in ("label", "detect"):
        raise VtsError(f"--circles must be label or detect, got {circles!r}")
    presses, bg, setup, warnings = load_presses(folder, mm_per_px=mm_per_px,
                                                background=background,
                                                estimate_background=estimate_background,
                                                circles=circles)
    n = len(presses)
    k = (n // 5 if n - n // 5 >= MIN_TRAIN else 0) if holdout is None else int(holdout)
    if k < 0:
        raise VtsError(f"--holdout must be >= 0, got {k}")
    if n < MIN_TRAIN + k:
        lost = setup["lost"]
        why = f" ({len(lost)} of {setup['n_entries']} without visible contact or with an " \
              f"implausible circle: {', '.join(lost)})" if lost else ""
        raise VtsError(f"too few presses: {n} usable{why}; need at least {MIN_TRAIN + k} "
                       f"({MIN_TRAIN} to train plus --holdout {k})", setup["root"])
    for w_ in warnings:
        say(f"warning: {w_}")
    rng = np.random.default_rng(seed)
    held_idx = sorted(rng.choice(n, k, replace=False).tolist()) if k else []
    train = [p for i, p in enumerate(presses) if i not in held_idx]
    held = [presses[i] for i in held_idx]
    say(f"{n} presses ({sum(p.circle_source == 'detected' for p in presses)} circles detected), "
        f"{len(train)} to train, {len(held)} held out; background: {setup['background']}")
    opts = dict(options or {})
    if method == "mlp":
        opts.setdefault("seed", seed)
        opts.setdefault("device", device)
    rim_scores = None
    if rim_cv:
        rim, rim_scores = choose_rim(train, bg, setup, method, rim=rim, blur_px=blur_px,
                                     seed=seed, options=opts, markers=markers)
        say("rim shrink by cross-validation over the training presses: " + ", ".join(
            f"{k} {v:.4f} mm" for k, v in rim_scores.items()) + f"; chose "
            f"{rim.shrink_px:g} px / {rim.shrink_frac:g}")
    t_fit = time.perf_counter()
    cal, (colour, xy, target, is_cap) = fit_calibration(train, bg, setup, method, rim=rim,
                                                        blur_px=blur_px, rng=rng, options=opts,
                                                        markers=markers)
    if cal.markers is not None:
        own = cal.markers.dot_blur_px
        say(f"marker gel: {cal.markers.n_dots} dots of {cal.markers.diameter_px:.1f} px in the "
            "background, divided out of the colour difference"
            + (f" and blurred by {own:.2g} px there" if own > 0 else "")
            + "; their dark cores left out of the fit, the darkest filled before integration")
        note = subsampled_colour_note(setup["sources"])
        if note:
            warnings.append(note)
            say(f"warning: {note}")
    fit_s = time.perf_counter() - t_fit
    mapping, zero, (h, w) = cal.mapping, cal.zero_map, setup["shape"]
    # Training error as the file will answer: f(c, x, y) - f(0, x, y) at the samples.
    xi = np.clip(((xy[:, 0] + 1) / 2 * w).astype(np.int64), 0, w - 1)
    yi = np.clip(((xy[:, 1] + 1) / 2 * h).astype(np.int64), 0, h - 1)
    pred = mapping.predict_flat(colour, xy) - zero[yi, xi]
    err = np.hypot(*(pred - target).T)
    say(f"fitted {method} on {colour.shape[0]} samples in {fit_s:.1f} s; gradient RMSE "
        f"{np.sqrt(np.mean(err[is_cap] ** 2)):.4f} on the caps")
    results = [evaluate_press(cal, p, solver=solver) for p in held]
    keys = ("gradient_rmse", "plane_aligned_rmse_mm", "contact_rmse_mm", "peak_depth_error_mm")
    cal.fit = {
        "train_gradient_rmse": float(np.sqrt(np.mean(err**2))),
        "train_gradient_rmse_cap": float(np.sqrt(np.mean(err[is_cap] ** 2))),
        "n_samples": int(colour.shape[0]),
        "n_samples_cap": int(is_cap.sum()),
        "seed": int(seed),
        "solver": solver,
        "background": setup["background"],
        "train_ids": [p.id for p in train],
        "dropped_ids": list(setup["lost"]),
        "circles_detected": sum(p.circle_source == "detected" for p in presses),
        "fit_seconds": round(fit_s, 3),
        **({} if rim_scores is None else {"rim_cv_mm": rim_scores}),
        "holdout": [{"id": r.press.id, "reference": r.reference,
                     **{kk: _num(r.errors[kk]) for kk in keys}} for r in results],
        "holdout_mean": {kk: _num(float(np.mean([r.errors[kk] for r in results])))
                         for kk in keys} if results else {},
    }
    if circles == "detect":  # the held-out presses scored against their labels as well
        cal.fit["holdout_vs_labels"] = _scored_against_labels(cal, results, setup["presses"],
                                                              solver)
    if results:  # every solver's absolute error and artefacts, side by side
        cal.fit["holdout_mean"].update({
            f"{s}_{kk}": _num(float(np.mean([r.by_solver[s][kk] for r in results])))
            for s in SOLVERS for kk in SOLVER_KEYS})
    examples = [] if results else [evaluate_press(cal, p, solver=solver, held_out=False)
                                   for p in train[:3]]
    return CalibrationRun(cal, results, warnings, time.perf_counter() - t0, examples,
                          setup["presses"], setup["frames"], setup["background_notes"])


def _scored_against_labels(cal: Calibration, results: list[HeldOut],
                           rows: list[dict[str, Any]], solver: str) -> dict[str, Any]:
    """Held-out presses of a run on detected circles scored against the spheres at their
    labelled circles (presses with a label and no simulated truth): the figure to set beside
    a run on the labels with the same seed."""
    labels = {r["id"]: r["label"] for r in rows if r.get("label") is not None}
    scored = []
    for r in results:
        lab = labels.get(r.press.id)
        if r.reference != "sphere" or lab is None:
            continue
        p = replace(r.press, x=lab["x"], y=lab["y"], r=lab["r"], circle_source="label")
        scored.append((r.press.id, evaluate_press(cal, p, solver=solver).errors))
    vals = [e["plane_aligned_rmse_mm"] for _, e in scored]
    return {"presses": len(scored), "ids": [i for i, _ in scored],
            "plane_aligned_rmse_mm": _num(float(np.mean(vals))) if vals else None}


def _num(v: float) -> float | None:
    """A JSON-safe number (None for NaN)."""
    return None if not math.isfinite(v) else float(v)


def __getattr__(name: str) -> Any:
    """`taxim_recordings`, now in `vtsbench.recordings.taxim`, still importable from here."""
    if name == "taxim_recordings":
        from ..recordings.taxim import taxim_recordings

        return taxim_recordings
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
