"""`vtsbench export-hf`: every sample of a built dataset in parquet under `hf/`, for `datasets`.

One parquet set per kind holds each sample once. The samples are grouped into *cells*: the
samples that fall in the same part of every split scheme of their kind (e.g. train of
unseen_objects, test of seen, fold3 of object_folds). Each cell is written to its own files, so
every split of every scheme is a list of whole files: the card's YAML `configs` give
`slip_<scheme>` and `static_<scheme>` configs whose splits point at those files, and no sample is
stored twice however many schemes hold it.

A dataset with episodes (format 1.2) also gets hf/episodes/ (hub_episodes: LeRobot v2.1's
meta files and one parquet file per episode, a row per frame with its timestamp), read by the
`episodes` config and one `episodes_<scheme>` config per split of episodes.

Columns (layout version `hub_rows.HUB_VERSION`): the index's labels (object, state and direction
as ClassLabel ids), then images that `datasets` decodes on access, so its Arrow cache is no larger
than the parquet: `rgb` as lossless TIFFs (a list of T for a slip sample; uint8), `depth` as 16-bit
TIFFs of the stored int16 counts (x the depth scale = the loader's mm, bit for bit), `contact` as
1-bit PNGs (decoding to bool), and `depth_preview`, a colour-mapped PNG of the depth for the Hub
viewer (not decoded by `datasets`). The arrow schema carries the `huggingface` features metadata
and the layout version.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ...errors import VtsError
from ..format.layout import CARD_PATH, HUB_DIR, INFO_PATH, KINDS
from .hub_layout import HubFile, HubLayout, config_name, split_name
from .hub_write import cells, schemes_of, write_kind

if TYPE_CHECKING:
    from ..read.loader import VtsDataset

def hub_configs(ds: VtsDataset, files: dict[str, list[HubFile]]
                ) -> tuple[dict[str, dict[str, list[str]]], dict[str, str]]:
    """Per config (`<kind>_all` and one per scheme), split -> the files of its samples."""
    configs: dict[str, dict[str, list[str]]] = {}
    kinds: dict[str, str] = {}
    for kind in ("slip", "static"):
        if not files.get(kind):
            continue
        cell_list = cells(ds, kind)
        schemes = schemes_of(ds, kind)
        for j, scheme in enumerate(schemes):
            name = config_name(kind, scheme)
            configs[name], kinds[name] = {}, kind
            for part in ds.parts(scheme):
                keep = {c for c, cell in enumerate(cell_list) if cell.parts[j] == part}
                configs[name][split_name(part)] = [f.path for f in files[kind] if f.cell in keep]
        configs[f"{kind}_all"] = {"full": [f.path for f in files[kind]]}
        kinds[f"{kind}_all"] = kind
    return configs, kinds


# -- export --------------------------------------------------------------------------------


@dataclass
class ExportResult:
    """What export_hf wrote, for the command's summary."""

    layout: HubLayout
    seconds: float
    kept: int = 0  # parquet files kept from an interrupted export

    def summary(self) -> str:
        """The one line `vtsbench export-hf` prints: rows, files, bytes, time, configs."""
        from .info import human

        lay = self.layout
        n = sum(f.rows for fs in lay.files.values() for f in fs)
        files = sum(len(fs) for fs in lay.files.values())
        kept = f" ({self.kept} kept from an interrupted export)" if self.kept else ""
        what = f"{n} samples in {files} parquet files"
        if lay.episodes is not None:
            eps = lay.episodes.files
            frames = f"{len(eps)} episodes ({sum(f.rows for f in eps)} frames) in {len(eps)} " \
                     "parquet files"
            what = f"{what} and {frames}" if files else frames
        return (f"{what} ({human(lay.nbytes())}) in {self.seconds:.1f} s{kept}; configs: "
                f"{', '.join(lay.all_configs())}")


#: The export's state folder inside its stage: a marker per finished parquet file.
EXPORT_WORK = ".export"


def export_stage(root: Path) -> Path:
    """The hidden folder beside a dataset where export-hf makes its next version:
    `.DATASET.hf.partial`."""
    return root.with_name(f".{root.name}.hf.partial")


def _link_dataset(root: Path, stage: Path) -> None:
    """Make the stage the dataset without its hub copy, card and info.json: every other file
    hard-linked (copied where the filesystem has no links), so no data is copied; the stage's
    own hub files and state are kept for the resume."""
    import os
    import shutil

    for p in stage.iterdir():
        if p.name not in (HUB_DIR, EXPORT_WORK):
            shutil.rmtree(p) if p.is_dir() and not p.is_symlink() else p.unlink()
    for dirpath, dirnames, filenames in os.walk(root):
        here = Path(dirpath)
        rel_dir = here.relative_to(root)
        if rel_dir == Path("."):
            dirnames[:] = [d for d in dirnames if d != HUB_DIR]
        (stage / rel_dir).mkdir(parents=True, exist_ok=True)
        for name in [*filenames, *(d for d in dirnames if (here / d).is_symlink())]:
            src, dst = here / name, stage / rel_dir / name
            if (rel_dir / name).as_posix() in (CARD_PATH, INFO_PATH):
                continue
            if src.is_symlink():
                os.symlink(os.readlink(src), dst)
                continue
            try:
                os.link(src, dst)
            except OSError:
                shutil.copy2(src, dst)
        dirnames[:] = [d for d in dirnames if not (here / d).is_symlink()]


def export_hf(dataset: str | Path, *, workers: int = 1, license: str = "unknown",
              progress: bool = False) -> ExportResult:
    """Write the hub copy of a built dataset into it (hf/, a new README.md) and record the new
    files in meta/info.json, so `vtsbench verify` still checks every file.

    The dataset is never half exported: its next version is made beside it, in
    `.DATASET.hf.partial` (its files hard-linked, the parquet files written there one by one,
    each through a temporary name and marked done, then the card and info.json), and swapped
    in as a whole by the same rename as `build --overwrite` (staging.commit). At every kill
    point DATASET is the previous complete dataset or the new one, and a rerun keeps the
    parquet files already finished (those whose dataset and schema have not changed).
    """
    import os
    import shutil
    import time

    from ...atomic import write_bytes_atomic
    from ..build.finish import hash_files
    from ..build.staging import commit, locked_stage, recover
    from ..read.loader import load
    from .hub_episodes import remove_episodes, write_episodes
    from .hub_layout import write_hub_card
    from .hub_rows import check_codecs

    t0 = time.perf_counter()
    if not re.fullmatch(r"[a-z0-9][a-z0-9.+-]{0,63}", license):
        raise VtsError(f"license must be a Hub license id (lower case, e.g. cc-by-4.0, mit, "
                       f"other), got {license!r}")
    check_codecs()
    given = Path(dataset)
    root = given.resolve()
    recover(root, export_stage(root), EXPORT_WORK)  # a killed export or build: put right
    ds = load(given)
    if ds.loc.remote:
        raise VtsError("export-hf writes into the dataset: give a local folder", given)
    if not os.access(root.parent, os.W_OK):
        raise VtsError(f"export-hf makes the new version beside the dataset (in "
                       f"{export_stage(root).name}), and this folder is not writable",
                       root.parent)
    with locked_stage(root, export_stage(root), EXPORT_WORK) as stage:
        _link_dataset(root, stage)
        files: dict[str, list[HubFile]] = {}
        digests: dict[str, str] = {}
        kept: list[str] = []
        n_frames = ds.info.episodes.frames if ds.info.episodes is not None else 0
        total = sum(len(ds.view(k)) for k in KINDS) + n_frames
        with _progress(progress, total) as advance:
            for kind in KINDS:
                if len(ds.view(kind)):
                    files[kind] = write_kind(ds, kind, stage, workers, advance,
                                             stage / EXPORT_WORK, given, digests, kept)
                else:
                    shutil.rmtree(stage / HUB_DIR / kind, ignore_errors=True)
            episodes = write_episodes(ds, stage, workers, advance, stage / EXPORT_WORK,
                                      given, digests, kept) if n_frames else None
        if episodes is None:
            remove_episodes(stage)
        configs, kinds = hub_configs(ds, files)
        layout = HubLayout(files, configs, kinds, episodes)
        write_hub_card(stage, ds, layout, license)
        info = ds.info
        keep = {k: v for k, v in info.files.items()
                if not k.startswith(f"{HUB_DIR}/") and k != CARD_PATH}
        new = hash_files(stage, lambda rel: rel.startswith(f"{HUB_DIR}/") or rel == CARD_PATH,
                         digests)
        info.files = dict(sorted({**keep, **new}.items()))
        write_bytes_atomic(stage / INFO_PATH, info.to_json().encode())
        commit(stage, root, EXPORT_WORK)
    return ExportResult(layout, time.perf_counter() - t0, len(kept))


class _progress:
    """A rich progress bar of samples written (a no-op callable when off)."""

    def __init__(self, on: bool, total: int) -> None:
        self.on, self.total = on, total
        self.bar: Any = None

    def __enter__(self) -> Callable[[int], None]:
        if not self.on:
            return lambda _n: None
        from ...progress import progress_bar

        self.bar = progress_bar()
        self.bar.__enter__()
        task = self.bar.add_task("samples", total=self.total)
        return lambda n: self.bar.advance(task, n)

    def __exit__(self, *exc: Any) -> None:
        if self.bar is not None:
            self.bar.__exit__(*exc)
