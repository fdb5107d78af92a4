"""`vtsbench push`: upload a built dataset folder to a Hugging Face Hub dataset repository.

The folder is checked first (`vtsbench verify --quick`: checksums, schemas, index, splits), so
a damaged copy is never published. The dry run lists what would be uploaded and needs no
network; the upload is `huggingface_hub.HfApi.upload_folder` (token from `hf auth login` or
HF_TOKEN, as huggingface_hub reads it).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from ...errors import VtsError
from ..format.layout import DATA_DIR, HUB_DIR

#: Never uploaded: hidden files (partial writes, caches) and build leftovers.
IGNORE = (".*", "**/.*", "**/*.tmp")
#: One part of a Hub repository id (namespace or name), as the Hub accepts it: letters, digits,
#: '.', '_', '-', neither starting nor ending with '.' or '-', at most 96 characters.
_REPO_PART = re.compile(r"[A-Za-z0-9_](?:[A-Za-z0-9._-]{0,94}[A-Za-z0-9_])?")


def check_repo_id(repo_id: str) -> str:
    """A Hub dataset repository id, NAMESPACE/NAME, checked as the Hub checks it (no '..' nor
    '--', no path of any other shape) before anything is read or sent: a one-line error."""
    parts = repo_id.split("/")
    bad = (len(parts) != 2 or not all(_REPO_PART.fullmatch(p) for p in parts)
           or ".." in repo_id or "--" in repo_id or repo_id.endswith(".git"))
    if bad:
        raise VtsError(f"repository id {repo_id[:100]!r} is not NAMESPACE/NAME (letters, digits, "
                       "'.', '_', '-', each part at most 96 characters, no '..' or '--', not "
                       "starting or ending with '.' or '-'), e.g. my-lab/tactile")
    return repo_id


@dataclass
class PushPlan:
    """The files an upload sends (relative paths and sizes), and what it leaves out."""

    files: list[tuple[str, int]]
    left_out: list[str]
    has_hub_copy: bool

    @property
    def nbytes(self) -> int:
        return sum(n for _, n in self.files)

    #: Said before an upload of a dataset without its parquet copy.
    NO_HUB_COPY = ("no hf/ folder: run `vtsbench export-hf` first for the Hub viewer and "
                   "datasets.load_dataset configs")

    def listing(self, repo_id: str) -> list[str]:
        """A dry run's lines: each file with its size, then what an upload would send."""
        from .info import human

        left = f"; leaving out {len(self.left_out)} Zarr files" if self.left_out else ""
        return [f"{human(size):>10}  {rel}" for rel, size in self.files] + [
            f"dry run: would upload {len(self.files)} files ({human(self.nbytes)}) to "
            f"datasets/{repo_id}{left}"]

    def uploaded(self, url: str) -> str:
        """The line printed after an upload."""
        from .info import human

        return f"uploaded {len(self.files)} files ({human(self.nbytes)}): {url}"


def push_plan(dataset: str | Path, zarr: bool = True, repo_id: str | None = None) -> PushPlan:
    """What `push` uploads: every file of the verified dataset (without data/ when zarr=False,
    which leaves a Hub repository that `datasets` reads but `vtsbench.load` cannot); repo_id,
    when given, is checked first."""
    from .verify import verify

    if repo_id is not None:
        check_repo_id(repo_id)
    root = Path(dataset)
    report = verify(root, decode=False)
    if not report.ok:
        more = f" (and {len(report.problems) - 1} more)" if len(report.problems) > 1 else ""
        raise VtsError(f"does not verify, not pushing: {report.problems[0]}{more}", root)
    files, left = [], []
    for p in sorted(root.rglob("*")):
        if not p.is_file():
            continue
        rel = p.relative_to(root).as_posix()
        if any(part.startswith(".") for part in rel.split("/")):
            continue
        if not zarr and rel.startswith(f"{DATA_DIR}/"):
            left.append(rel)
            continue
        files.append((rel, p.stat().st_size))
    return PushPlan(files, left, (root / HUB_DIR).is_dir())


def push(dataset: str | Path, repo_id: str, *, zarr: bool = True, private: bool = False,
         revision: str | None = None, message: str | None = None) -> str:
    """Create the dataset repository if needed and upload the folder; returns the commit URL."""
    from huggingface_hub import HfApi

    plan = push_plan(dataset, zarr, repo_id)
    api = HfApi()
    try:
        api.create_repo(repo_id, repo_type="dataset", private=private, exist_ok=True)
        info = api.upload_folder(
            folder_path=str(dataset), repo_id=repo_id, repo_type="dataset", revision=revision,
            commit_message=message or f"vtsbench dataset ({len(plan.files)} files)",
            ignore_patterns=[*IGNORE, *([] if zarr else [f"{DATA_DIR}/**"])])
    except Exception as e:  # network, authentication and Hub errors of any kind
        text = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise VtsError(f"upload to {repo_id} failed ({type(e).__name__}: {text})",
                       dataset) from None
    return str(getattr(info, "commit_url", info))
