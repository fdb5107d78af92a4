"""Writing a submission: the CSV of prediction rows `vtsbench eval` reads and its metadata
(OUT.meta.json: method, recipe, dataset version and digest, seeds, vtsbench version)."""

from __future__ import annotations

import csv
import json
from collections.abc import Iterable
from pathlib import Path
from typing import Any

#: The columns of a submission row, in the order they are written.
ROW_COLUMNS = ("sample_id", "task", "pred")


def default_meta_path(path: Path) -> Path:
    """SUBMISSION.meta.json beside the submission (its suffix replaced): where eval looks."""
    return path.with_name(f"{path.stem}.meta.json")


def write_submission(rows: Iterable[dict[str, Any]], out: str | Path, *, method: str,
                     dataset_path: str | Path, recipe: str | None = None,
                     seeds: list[int] | None = None, extra: dict[str, Any] | None = None
                     ) -> tuple[Path, Path]:
    """Write rows as a submission CSV and its metadata (OUT.meta.json) beside it."""
    from vtsbench.dataset.read.loader import load

    rows = list(rows)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    extra_cols = sorted({k for r in rows for k in r if k not in ROW_COLUMNS},
                        key=lambda k: (not k.startswith("score_"), len(k), k))
    cols = [*ROW_COLUMNS, *extra_cols]
    from vtsbench.atomic import replacing, write_text_atomic

    with replacing(out) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=cols)
        w.writeheader()
        for r in rows:
            w.writerow({c: r.get(c, "") for c in cols})
    info = load(dataset_path).info

    meta: dict[str, Any] = {"method": method, "recipe": recipe,
                            "dataset_version": info.dataset_version,
                            "dataset_sha256": info.dataset_sha256,
                            "vtsbench_version": _version()}
    if seeds is not None:
        meta["seeds"] = seeds
    meta.update(extra or {})
    meta_path = default_meta_path(out)
    write_text_atomic(meta_path, json.dumps(meta, indent=1, sort_keys=True) + "\n")
    return out, meta_path


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("vtsbench")
    except PackageNotFoundError:  # pragma: no cover - running from a bare checkout
        return "0+unknown"
