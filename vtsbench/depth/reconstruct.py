"""Images to depth: the calibration's gradients, integrated by a Poisson solver.

    reconstruct(images, calibration)  RGB (..., H, W, 3) -> depth (..., H, W) float32 mm

The numpy path runs by default; with `device` ("cuda", "cpu", or "auto" = CUDA when torch sees
one) the mapping and the integration run in torch on that device. `depth_folder` is the
`vtsbench depth` command: an image, a folder of images or a video in, a `.npy` (float32 mm) and
a colour-mapped `.png` per frame out.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import VtsError
from .calibration import Calibration
from .mapping import resolve_device

SOLVERS = ("dct", "dst", "masked")


def _check_images(images: Any, calibration: Calibration) -> np.ndarray:
    arr = np.asarray(images)
    if arr.dtype == bool or not (np.issubdtype(arr.dtype, np.integer)
                                 or np.issubdtype(arr.dtype, np.floating)):
        raise VtsError(f"images must be RGB numbers (uint8 or float 0..255), got {arr.dtype}")
    calibration._check_shape(arr.shape)
    if np.issubdtype(arr.dtype, np.floating) and not np.isfinite(arr).all():
        bad = int((~np.isfinite(arr)).sum())
        raise VtsError(f"images contain NaN or inf ({bad} values)")
    return arr


def _mask_for(mask: Any, lead: tuple[int, ...], hw: tuple[int, int]) -> np.ndarray | None:
    if mask is None:
        return None
    m = np.asarray(mask)
    if m.dtype != bool:
        raise VtsError(f"mask must be boolean, got {m.dtype}")
    try:
        return np.broadcast_to(m, (*lead, *hw)).reshape(-1, *hw)
    except ValueError:
        raise VtsError(f"mask of shape {m.shape} does not fit frames {(*lead, *hw)}") from None


def reconstruct(images: Any, calibration: Calibration, *, solver: str = "dct",
                mask: Any = None, device: str | None = None, batch: int = 8) -> np.ndarray:
    """Depth (mm, positive into the gel) of RGB frames (..., H, W, 3), float32 (..., H, W).

    solver: "dct" (free border, border median at 0), "dst" (zero depth beyond the frame) or
    "masked" (zero depth off the mask; without a mask, the pixels whose colour differs from the
    calibration's background, vtsbench.depth.mask.mask_from_images). mask: (..., H, W) bool,
    masked solver only. device: None for numpy; "auto" for CUDA when present (else numpy);
    "cpu" or "cuda[:n]" for torch there. batch: frames per step.
    """
    if solver not in SOLVERS:
        raise VtsError(f"unknown solver {solver!r} (use one of {', '.join(SOLVERS)})")
    if mask is not None and solver != "masked":
        raise VtsError(f"a mask is used only by the masked solver, not {solver!r}")
    arr = _check_images(images, calibration)
    h, w = calibration.resolution
    lead = arr.shape[:-3]
    frames = arr.reshape(-1, h, w, 3)
    masks = _mask_for(mask, lead, (h, w))
    dev = resolve_device(device)
    out = np.empty((frames.shape[0], h, w), np.float32)
    step = max(1, int(batch))
    for s in range(0, frames.shape[0], step):
        chunk = frames[s:s + step]
        m = None if masks is None else masks[s:s + step]
        if solver == "masked" and m is None:
            from .mask import mask_from_images

            m = mask_from_images(chunk, calibration.background)
        if dev is None:
            out[s:s + step] = _numpy_depth(chunk, calibration, solver, m)
        else:
            out[s:s + step] = _torch_depth(chunk, calibration, solver, m, dev)
    return out.reshape(*lead, h, w)


def _numpy_depth(frames: np.ndarray, cal: Calibration, solver: str,
                 mask: np.ndarray | None) -> np.ndarray:
    from .poisson import integrate

    if solver != "masked" and cal.markers is None and frames.dtype == np.uint8:
        # a frame at a time through the build's preallocated path: the same float32 numbers
        # (vtsbench.dataset.depthmaps; tests/depth/test_build_depth.py), arrays that stay in cache
        maker = _maker(cal)
        return np.stack([maker.depth(f, solver) for f in frames])
    g = cal.gradients(frames)
    return integrate(g[..., 0], g[..., 1], method=solver, mask=mask, mm_per_px=cal.mm_per_px,
                     dtype=np.float32)


def _maker(cal: Calibration) -> Any:
    """The calibration's DepthMaker, made once (its lookup tables and buffers)."""
    from .depthmaps import DepthMaker

    key = (cal.mapping, cal.zero_map, cal.background, cal.mm_per_px, cal.blur_px,
           cal.colour_limit_dn)
    held = cal.__dict__.get("_maker")
    if held is None or len(held[0]) != len(key) or \
            not all(a is b or a == b for a, b in zip(held[0], key, strict=True)
                    if not isinstance(a, np.ndarray)) or \
            not all(a is b for a, b in zip(held[0], key, strict=True) if isinstance(a, np.ndarray)):
        held = cal.__dict__["_maker"] = (key, DepthMaker(cal))
    return held[1]


def _torch_depth(frames: np.ndarray, cal: Calibration, solver: str, mask: np.ndarray | None,
                 device: str) -> np.ndarray:
    try:
        import torch

        from .poisson_torch import integrate_torch
    except ImportError:
        raise VtsError(f"device {device!r} needs torch (pip install 'vtsbench[torch]'); "
                       "leave the device out for the numpy path") from None
    try:
        dev = torch.device(device)
        x = torch.from_numpy(np.ascontiguousarray(frames)).to(dev)
    except (RuntimeError, AssertionError) as e:
        raise VtsError(f"device {device!r} is not usable here ({str(e).splitlines()[0]})") \
            from None
    with torch.no_grad():
        g = cal.gradients_torch(x)
        tm = None if mask is None else torch.from_numpy(np.ascontiguousarray(mask)).to(dev)
        z = integrate_torch(g[..., 0], g[..., 1], method=solver, mask=tm,
                            mm_per_px=cal.mm_per_px)
    return z.to(torch.float32).cpu().numpy()


# -- files ------------------------------------------------------------------------------------


#: The colour of the most negative depth shown (above the gel's rest surface): red, so that a
#: reconstruction's negative depth stands out against the viridis scale of positive depth.
NEGATIVE_RGB = (230, 40, 40)


def colourise(depth: np.ndarray, vmax: float | None = None,
              vmin: float | None = None) -> np.ndarray:
    """A depth map (mm) as RGB uint8: 0 to vmax on viridis (0 dark violet, vmax yellow) and
    vmin to 0 (negative depth, above the rest surface) from red to viridis' 0, so negative depth
    is visible, never clipped to 0.

    vmax defaults to the frame's 99.9th percentile, at least 0.05 mm, so an untouched frame is
    not stretched into noise; vmin to the frame's 0.1th percentile when below -0.005 mm, else
    -vmax / 10. Values beyond the range take the end colours.
    """
    from matplotlib import colormaps

    d = np.nan_to_num(np.asarray(depth, np.float32))
    vmax, vmin = colour_range(d, vmax, vmin)
    lut = (colormaps["viridis"](np.linspace(0, 1, 256))[:, :3] * 255).round().astype(np.uint8)
    t = np.clip(d / vmax, 0.0, 1.0)
    out = lut[(t * 255).round().astype(np.int64)]
    neg = d < 0
    if neg.any():
        u = np.clip(d[neg] / vmin, 0.0, 1.0)[:, None]
        out[neg] = ((1 - u) * lut[0] + u * np.array(NEGATIVE_RGB)).round().astype(np.uint8)
    return out


def colour_range(d: np.ndarray, vmax: float | None, vmin: float | None) -> tuple[float, float]:
    """(vmax, vmin) of colourise: the given values, else the frame's (see colourise)."""
    if vmax is None:
        vmax = max(float(np.percentile(d, 99.9)), 0.05) if d.size else 0.05
    if vmin is None:
        low = float(np.percentile(d, 0.1)) if d.size else 0.0
        vmin = low if low < -0.005 else -vmax / 10
    if not (math.isfinite(vmax) and math.isfinite(vmin) and vmin < 0 < vmax):
        raise VtsError(f"the colour range must have MIN < 0 < MAX, got {vmin:g},{vmax:g}")
    return float(vmax), float(vmin)


def with_colour_bar(rgb: np.ndarray, vmax: float, vmin: float) -> np.ndarray:
    """The colourised frame with a colour bar on its right: the scale from vmin to vmax with
    its ends and 0 labelled in mm (OpenCV text: a bar per frame costs well under a millisecond,
    a matplotlib figure about 50 ms)."""
    import cv2

    h = rgb.shape[0]
    bar_w, text_w = max(6, h // 24), max(48, h // 5)
    levels = np.linspace(vmax, vmin, h, dtype=np.float32)[:, None]
    bar = colourise(np.repeat(levels, bar_w, axis=1), vmax, vmin)
    panel = np.full((h, text_w, 3), 255, np.uint8)
    scale = max(0.3, h / 700)
    thick = 1
    for v in (vmax, 0.0, vmin):
        y = round((vmax - v) / (vmax - vmin) * (h - 1))
        cv2.line(panel, (0, y), (3, y), (0, 0, 0), 1)
        label = f"{v:+.3g}" if v else "0"
        (_, th), _ = cv2.getTextSize(label, cv2.FONT_HERSHEY_SIMPLEX, scale, thick)
        ty = min(max(y + th // 2, th + 1), h - 2)
        cv2.putText(panel, label, (5, ty), cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0),
                    thick, cv2.LINE_AA)
    cv2.putText(panel, "mm", (5, h // 2 + int(14 * scale * 2)), cv2.FONT_HERSHEY_SIMPLEX,
                scale, (90, 90, 90), thick, cv2.LINE_AA)
    gap = np.full((h, 2, 3), 255, np.uint8)
    return np.concatenate([rgb, gap, bar, panel], axis=1)


def _frames(path: Path, batch: int, size: tuple[int, int] | None = None
            ) -> Iterator[tuple[list[str], np.ndarray]]:
    """(names, frames) in batches from an image, an image folder or a video; a frame of
    another size than `size`, or two images of one stem (a.png, a.jpg: one output name), is a
    one-line error naming the file before anything is written for it."""
    from ..recordings.media import Capture, folder_frames, media_kind, read_image

    if not path.exists():
        raise VtsError("not found (expected an image, a folder of images or a video)", path)
    kind = media_kind(path)
    if kind == "image":
        yield [path.stem], read_image(path)[None]
    elif kind == "folder":
        files = folder_frames(path)
        if not files:
            raise VtsError("folder holds no images", path)
        stems: dict[str, Path] = {}
        for f in files:
            if f.stem in stems:
                raise VtsError(f"{stems[f.stem].name} and {f.name} would both be written as "
                               f"{f.stem}.npy; rename one", path)
            stems[f.stem] = f
        for s in range(0, len(files), batch):
            part = files[s:s + batch]
            imgs = [read_image(f) for f in part]
            for f, img in zip(part, imgs, strict=True):
                if size is not None and img.shape[:2] != tuple(size):
                    raise VtsError(f"frame is {img.shape[0]}x{img.shape[1]}, the others and the "
                                   f"calibration {size[0]}x{size[1]}", f)
            yield [f.stem for f in part], np.stack(imgs)
    else:
        with Capture(str(path)) as cap:
            names: list[str] = []
            buf: list[np.ndarray] = []
            i = 0
            while True:
                f = cap.read()
                if f is None:
                    break
                names.append(f"{path.stem}_{i:05d}")
                buf.append(f)
                i += 1
                if len(buf) == batch:
                    yield names, np.stack(buf)
                    names, buf = [], []
            if buf:
                yield names, np.stack(buf)
            if i == 0:
                raise VtsError("video has no readable frame", path)


GLOB_CHARS = "*?["


def expand_inputs(paths: list[str | Path]) -> list[Path]:
    """The inputs of `vtsbench depth`: each path as is, or a glob's matches (sorted; '**'
    recurses); a glob that matches nothing, or a missing path, is an error naming it."""
    import glob

    out: list[Path] = []
    for p in paths:
        text = str(p)
        if not Path(text).exists() and any(c in text for c in GLOB_CHARS):
            hits = sorted(glob.glob(text, recursive=True))
            if not hits:
                raise VtsError("the pattern matches no file", text)
            out += [Path(h) for h in hits]
        elif not Path(text).exists():
            raise VtsError("not found (expected an image, a folder of images or a video)", text)
        else:
            out.append(Path(text))
    seen: set[Path] = set()
    return [p for p in out if not (p.resolve() in seen or seen.add(p.resolve()))]


def parse_range(text: str | None) -> tuple[float, float] | None:
    """--range MIN,MAX (mm) as (vmin, vmax), or None; one-line errors."""
    if text is None:
        return None
    try:
        lo, hi = (float(v) for v in text.split(","))
    except ValueError:
        raise VtsError(f"--range expects MIN,MAX in mm such as -0.2,1.5, got {text!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < 0 < hi):
        raise VtsError(f"--range needs finite MIN < 0 < MAX (0, the rest surface, must be "
                       f"inside), got {text!r}")
    return lo, hi


def depth_paths(inputs: list[str | Path], calibration: str | Path, out: str | Path, *,
                solver: str = "dct", device: str | None = "auto", batch: int = 8,
                value_range: tuple[float, float] | None = None,
                log: Callable[[str], None] | None = None) -> int:
    """`vtsbench depth` on several images, folders, videos or globs. With several inputs, the
    frames of a folder or a video go to OUT/<its name>/; images go to OUT. Returns frames done."""
    paths = expand_inputs(inputs)
    out = Path(out)
    several = len(paths) > 1
    names: dict[Path, Path] = {}
    for p in paths:  # where each input's maps go, refusing two inputs with the same target
        from ..recordings.media import media_kind

        target = out / p.stem if several and media_kind(p) != "image" else out
        key = target / p.stem if media_kind(p) == "image" else target
        if key in names:
            raise VtsError(f"two inputs write the same depth maps ({names[key]} and {p}); "
                           "rename one or run them separately", p)
        names[key] = p
    n = 0
    for k, p in enumerate(paths, start=1):
        from ..recordings.media import media_kind

        target = out / p.stem if several and media_kind(p) != "image" else out
        done = depth_folder(p, calibration, target, solver=solver, device=device, batch=batch,
                            value_range=value_range)
        n += done
        if log is not None:
            log(f"depth: {k}/{len(paths)} {p}: {done} frame(s) -> {target}")
    return n


def depth_folder(images: str | Path, calibration: str | Path, out: str | Path, *,
                 solver: str = "dct", device: str | None = "auto", batch: int = 8,
                 value_range: tuple[float, float] | None = None) -> int:
    """Write <name>.npy (float32 mm) and <name>.png (colour-mapped, with a colour bar; the
    frame's own range, or value_range (MIN, MAX) mm for every frame) per frame; frames done."""
    import io

    from ..atomic import write_bytes_atomic
    from ..recordings.media import write_png
    from .calibration import load_calibration

    images, out = Path(images), Path(out)
    cal = load_calibration(calibration)
    n = 0
    for names, frames in _frames(images, max(1, batch), cal.resolution):
        if n == 0 and frames.shape[1:3] != cal.resolution:
            h, w = frames.shape[1:3]
            raise VtsError(f"frames are {h}x{w} but calibration {calibration} is for "
                           f"{cal.resolution[0]}x{cal.resolution[1]} (sensor {cal.sensor})",
                           images)
        depth = reconstruct(frames, cal, solver=solver, device=device, batch=batch)
        if n == 0:
            out.mkdir(parents=True, exist_ok=True)
        for name, d in zip(names, depth, strict=True):
            buf = io.BytesIO()
            np.save(buf, d.astype(np.float32), allow_pickle=False)
            write_bytes_atomic(out / f"{name}.npy", buf.getvalue())
            lo, hi = value_range if value_range is not None else (None, None)
            vmax, vmin = colour_range(d, hi, lo)
            write_png(out / f"{name}.png", with_colour_bar(colourise(d, vmax, vmin), vmax, vmin))
            n += 1
    return n
