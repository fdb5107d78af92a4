"""Ball-press calibration data in the two layouts labs already have, as a recordings folder.

- A **gs_sdk calibration folder**: `catalog.csv` (`experiment_reldir`, `diameter(mm)`), one
  folder per press with `gelsight.png` (written by OpenCV; `gelsight.jpg` and other image
  types are read too) and the labelled circle `label.npz`
  (`center` x, y and `radius`, px), and `background.png`; the sensor's scale in a config YAML
  whose `ppmm` key holds millimetres per pixel. The files stay where they are: the manifest
  written points back to them.
- A **Taxim data pack** (`.npz`: `f0`, `imgs`, `touch_center`, `touch_radius`): its frames are
  written out as PNGs (`taxim.taxim_recordings`).

Every file is read by a library with a size limit, and checked before anything is written.
"""

from __future__ import annotations

import io
import math
import os
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

import numpy as np

from ..errors import VtsError
from .importer import first_repeat, safe_id
from .manifest import MANIFEST_NAME, Circle, Entry, Manifest, Session, Source, save_manifest
from .media import probe

CATALOG = "catalog.csv"
PRESS_IMAGE = "gelsight"  # gelsight.png as gs_sdk writes it; .jpg etc. from other cameras
LABEL = "label.npz"
BACKGROUND = "background"
CATALOG_DIR, CATALOG_DIAMETER = "experiment_reldir", "diameter(mm)"
MAX_LABEL_BYTES = 1 << 20  # a label is two numbers; 1 MiB leaves room and stops a zip bomb
MAX_CONFIG_BYTES = 1 << 20
MAX_PRESSES = 100_000


@dataclass(frozen=True)
class ImportSummary:
    """What an import wrote, for the command's summary line."""

    path: Path  # the recordings.json written
    layout: str  # "gs_sdk" or "taxim"
    presses: int
    labelled: int
    mm_per_px: float | None
    background: bool
    ball_radii_mm: tuple[float, ...]


def read_small_npz(path: Path, what: str, limit: int = MAX_LABEL_BYTES) -> dict[str, np.ndarray]:
    """The arrays of a small .npz (no pickled objects), the archive and every array within
    `limit` bytes before any is decompressed; a one-line VtsError otherwise."""
    from ..jsonio import read_bytes

    data = read_bytes(path, what, limit)
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as zf:
            big = [i.filename for i in zf.infolist() if i.file_size > limit]
        if big:
            raise VtsError(f"{what}: array {big[0]!r} unpacks to more than {limit} bytes", path)
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except (ValueError, OSError, EOFError, zipfile.BadZipFile, KeyError) as e:
        reason = str(e).splitlines()[0][:120] if str(e) else type(e).__name__
        raise VtsError(f"not a readable {what} ({reason})", path) from None


def read_label(path: Path) -> Circle:
    """A gs_sdk `label.npz` as a Circle: `center` (x, y) and `radius` in pixels."""
    arrays = read_small_npz(path, "label file")
    missing = [k for k in ("center", "radius") if k not in arrays]
    if missing:
        raise VtsError(f"label file has no '{missing[0]}' array (found: "
                       f"{', '.join(sorted(arrays)) or 'none'})", path)
    centre, radius = arrays["center"], arrays["radius"]
    if centre.dtype.kind not in "iuf" or radius.dtype.kind not in "iuf":
        raise VtsError("label file: center and radius must be numbers", path)
    if centre.size != 2 or radius.size != 1:
        raise VtsError(f"label file: center must hold x and y and radius one number (shapes "
                       f"{centre.shape} and {radius.shape})", path)
    x, y = (float(v) for v in centre.reshape(2))
    r = float(radius.reshape(()))
    if not all(math.isfinite(v) for v in (x, y, r)):
        raise VtsError("label file: center and radius must be finite", path)
    if r <= 0:
        raise VtsError(f"label file: radius {r:g} is not positive", path)
    return Circle(x, y, r)


def read_gs_config(path: Path) -> tuple[float, tuple[int, int] | None]:
    """A gs_sdk sensor config (YAML): its `ppmm` (millimetres per pixel, despite the name) and,
    when given, its frame size (`imgh`, `imgw`)."""
    import yaml

    from ..jsonio import read_bytes

    data = read_bytes(path, "sensor config", MAX_CONFIG_BYTES)
    try:
        doc = yaml.safe_load(data)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        raise VtsError(f"invalid YAML{where}", path) from None
    if not isinstance(doc, dict) or "ppmm" not in doc:
        raise VtsError("sensor config has no 'ppmm' (mm per pixel) key", path)
    mm = doc["ppmm"]
    if isinstance(mm, bool) or not isinstance(mm, (int, float)) or not math.isfinite(mm) \
            or mm <= 0:
        raise VtsError(f"sensor config: ppmm {mm!r} is not a positive number", path)
    size = None
    h, w = doc.get("imgh"), doc.get("imgw")
    if all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in (h, w)):
        size = (int(h), int(w))
    return float(mm), size


def _safe_reldir(text: str, row: int, catalog: Path) -> str:
    """A catalog's experiment folder as a relative POSIX path that stays inside the folder."""
    rel = text.strip().replace("\\", "/")
    parts = PurePosixPath(rel).parts
    if not rel or rel.startswith("/") or (parts and ":" in parts[0]) or ".." in parts:
        raise VtsError(f"row {row}: {CATALOG_DIR} {text!r} must be a folder inside the "
                       "calibration folder", catalog)
    return PurePosixPath(*[p for p in parts if p != "."]).as_posix()


def read_catalog(folder: Path) -> list[tuple[str, float]]:
    """The (experiment folder, ball diameter in mm) rows of a gs_sdk `catalog.csv`."""
    from ..jsonio import read_csv
    from ..limits import MAX_MM

    catalog = folder / CATALOG
    rows = read_csv(catalog, "catalog")
    header = [h.lower() for h in rows[0]] if rows else []
    for col in (CATALOG_DIR, CATALOG_DIAMETER):
        if col not in header:
            raise VtsError(f"catalog has no '{col}' column (found: "
                           f"{', '.join(header) or 'no header'})", catalog)
    i_dir, i_dia = header.index(CATALOG_DIR), header.index(CATALOG_DIAMETER)
    if len(rows) - 1 > MAX_PRESSES:
        raise VtsError(f"catalog lists {len(rows) - 1} presses, more than {MAX_PRESSES}", catalog)
    out: list[tuple[str, float]] = []
    seen: set[str] = set()
    for n, cells in enumerate(rows[1:], start=2):
        cells = cells + [""] * (len(header) - len(cells))
        rel = _safe_reldir(cells[i_dir], n, catalog)
        try:
            dia = float(cells[i_dia])
        except ValueError:
            raise VtsError(f"row {n}: diameter {cells[i_dia]!r} is not a number", catalog) \
                from None
        if not (math.isfinite(dia) and 0 < dia <= 2 * MAX_MM):
            raise VtsError(f"row {n}: diameter {cells[i_dia]!r} is not a positive size in mm",
                           catalog)
        if rel in seen:
            raise VtsError(f"row {n}: {rel!r} is listed twice", catalog)
        seen.add(rel)
        out.append((rel, dia))
    if not out:
        raise VtsError("catalog lists no press", catalog)
    return out


def find_image(folder: Path, stem: str) -> Path | None:
    """folder/stem.png, or the one other image file of that stem (.jpg, .bmp...)."""
    from .media import IMAGE_EXTS

    png = folder / f"{stem}.png"
    if png.is_file():
        return png
    hits = sorted(p for p in folder.glob(f"{stem}.*") if p.suffix.lower() in IMAGE_EXTS)
    if len(hits) > 1:
        raise VtsError(f"{len(hits)} images named {stem}: {', '.join(p.name for p in hits)}",
                       folder)
    return hits[0] if hits else None


def gs_sdk_manifest(folder: Path, home: Path, *, mm_per_px: float | None = None,
                    config: Path | None = None, sensor: str = "gelsight",
                    warn: Callable[[str], None] | None = None) -> Manifest:
    """A manifest of a gs_sdk calibration folder's presses, with paths relative to `home`."""
    say = warn or (lambda _msg: None)
    folder, home = Path(folder), Path(home)
    if not folder.is_dir():
        raise VtsError("not a folder", folder)
    if not (folder / CATALOG).exists():
        raise VtsError(f"no {CATALOG}: not a gs_sdk calibration folder", folder)
    rows = read_catalog(folder)
    cfg_size = None
    if config is not None:
        cfg_mm, cfg_size = read_gs_config(Path(config))
        if mm_per_px is None:
            mm_per_px = cfg_mm
        elif not math.isclose(cfg_mm, mm_per_px, rel_tol=1e-6):
            say(f"--mm-per-px {mm_per_px:g} used; {config} says ppmm {cfg_mm:g}")

    def ref(path: Path) -> str:
        return Path(os.path.relpath(path, home)).as_posix()

    size: tuple[int, int] | None = None
    entries: list[Entry] = []
    for rel, dia in rows:
        if not (folder / rel).is_dir():
            raise VtsError(f"no folder for the catalog's {rel!r}", folder / rel)
        image = find_image(folder / rel, PRESS_IMAGE)
        if image is None:
            raise VtsError(f"no {PRESS_IMAGE}.png (or .jpg...) for the catalog's {rel!r}",
                           folder / rel)
        pr = probe(image)
        if pr.kind != "image":
            raise VtsError(f"not an image ({pr.kind})", image)
        if size is None:
            size = (pr.height, pr.width)
        elif (pr.height, pr.width) != size:
            raise VtsError(f"frame is {pr.height}x{pr.width}, the first press "
                           f"{size[0]}x{size[1]}", image)
        label = folder / rel / LABEL
        circle = read_label(label) if label.exists() else None
        entries.append(Entry(safe_id(rel, "press"), "press", "s0", Source(ref(image)),
                             object="calibration_ball", ball_radius_mm=dia / 2, circle=circle,
                             meta={"experiment_reldir": rel}))
    assert size is not None
    dup = first_repeat([e.id for e in entries])
    if dup is not None:
        raise VtsError(f"two experiment folders map to the press id '{dup}'", folder / CATALOG)
    if cfg_size is not None and cfg_size != size:
        say(f"{config} gives frames of {cfg_size[0]}x{cfg_size[1]}; the presses are "
            f"{size[0]}x{size[1]} (the presses' size is used)")
    background = None
    bg = find_image(folder, BACKGROUND)
    if bg is not None:
        pb = probe(bg)
        if (pb.height, pb.width) != size:
            raise VtsError(f"background is {pb.height}x{pb.width}, the presses "
                           f"{size[0]}x{size[1]}", bg)
        background = ref(bg)
    scale = None if mm_per_px is None else (float(mm_per_px), float(mm_per_px))
    return Manifest(sessions=[Session("s0", sensor, size, scale, background=background)],
                    entries=entries, name=folder.resolve().name,
                    description=f"gs_sdk calibration folder ({len(entries)} ball presses)",
                    created_by="vtsbench import-presses")


def import_presses(src: str | Path, out: str | Path, *, mm_per_px: float | None = None,
                   ball_radius_mm: float | None = None, config: Path | None = None,
                   sensor: str | None = None, overwrite: bool = False,
                   warn: Callable[[str], None] | None = None) -> ImportSummary:
    """Turn a gs_sdk calibration folder or a Taxim data pack into a recordings folder at `out`.

    A gs_sdk folder is described in place (recordings.json in `out`, pointing back to its
    files; `out` may be the folder itself); a Taxim pack's frames are written into `out`.
    recordings.json is written last and atomically, so an interrupted import never looks done.
    """
    src, out = Path(src), Path(out)
    target = out / MANIFEST_NAME
    if target.exists() and not overwrite:
        raise VtsError("already exists (use --overwrite to replace it)", target)
    if src.is_dir():
        if ball_radius_mm is not None:
            raise VtsError("--ball-radius-mm is for Taxim packs: a gs_sdk catalog gives each "
                           "press's ball diameter", src / CATALOG)
        out.mkdir(parents=True, exist_ok=True)
        m = gs_sdk_manifest(src, out, mm_per_px=mm_per_px, config=config,
                            sensor=sensor or "gelsight", warn=warn)
        path = save_manifest(out, m)
        layout = "gs_sdk"
    elif src.is_file():
        if config is not None:
            mm_cfg, _ = read_gs_config(Path(config))
            mm_per_px = mm_per_px if mm_per_px is not None else mm_cfg
        from .taxim import taxim_recordings

        kw = {k: v for k, v in (("ball_radius_mm", ball_radius_mm), ("mm_per_px", mm_per_px))
              if v is not None}
        if len(kw) < 2:
            say = warn or (lambda _msg: None)
            say("a Taxim pack records neither ball nor scale: using Taxim's dataPack_small "
                "(2 mm ball, 0.1245 mm/px) for what is not given (--ball-radius-mm, "
                "--mm-per-px)")
        taxim_recordings(src, out, sensor=sensor or "gelsight-taxim", **kw)
        from .manifest import load_manifest

        m, path, layout = load_manifest(out), target, "taxim"
    else:
        what = "not a folder or a regular file" if src.exists() else "not found"
        raise VtsError(f"{what}: give a gs_sdk calibration folder (with catalog.csv) or a "
                       "Taxim data pack (.npz)", src)
    radii = tuple(sorted({e.ball_radius_mm for e in m.entries if e.ball_radius_mm}))
    s = m.sessions[0]
    return ImportSummary(path, layout, len(m.entries), sum(e.circle is not None for e in m.entries),
                         None if s.mm_per_px is None else s.mm_per_px[0],
                         s.background is not None, radii)


__all__ = ["ImportSummary", "gs_sdk_manifest", "import_presses", "read_catalog",
           "read_gs_config", "read_label", "read_small_npz"]
