"""The parquet index of a dataset (`index/static.parquet`, `index/slip.parquet`): write and read.

Rows are written in Zarr row order with the schema of `schema.index_schema(kind)` (its variant
with nullable mm_per_px columns when a sample's scale is unknown, which only a build without
depth allows); the writer's settings are fixed, so the same rows give the same bytes.
"""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ..errors import VtsError
from .schema import SampleMeta, extra_column_name, index_schema, index_schema_of

#: Parquet settings: zstd pages, one row group (an index is small), statistics on.
PARQUET_OPTIONS: dict[str, Any] = {"compression": "zstd", "compression_level": 3,
                                   "use_dictionary": True, "write_statistics": True,
                                   "row_group_size": 1 << 20}


def index_bytes(kind: str, metas: Sequence[SampleMeta],
                extra: Mapping[str, Sequence[str | None]] | None = None) -> bytes:
    """The parquet file of one kind's index; rows must be in row order 0..N-1.

    extra: more string columns (name -> one value per row, None where a row has none), after
    the fixed ones in name order: the recordings' own fields, which `where()` filters on."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    for i, m in enumerate(metas):
        if m.kind != kind or m.row != i:
            raise ValueError(f"index row {i}: sample {m.sample_id!r} ({m.kind}, row {m.row}) is "
                             f"out of place in the {kind} index")
    known = all(m.mm_per_px_x is not None and m.mm_per_px_y is not None for m in metas)
    table = pa.Table.from_pylist([m.to_row() for m in metas], schema=index_schema(kind, known))
    for name in sorted(extra or {}):
        values = list((extra or {})[name])
        if len(values) != len(metas) or extra_column_name(name) != name:
            raise ValueError(f"extra index column {name!r}: bad name or {len(values)} values "
                             f"for {len(metas)} rows")
        table = table.append_column(pa.field(name, pa.string(), nullable=True),
                                    pa.array(values, pa.string()))
    buf = io.BytesIO()
    pq.write_table(table, buf, **PARQUET_OPTIONS)
    return buf.getvalue()


def write_index(path: Path, kind: str, metas: Sequence[SampleMeta],
                extra: Mapping[str, Sequence[str | None]] | None = None) -> None:
    """Write one kind's index atomically (extra: see index_bytes)."""
    from ..atomic import write_bytes_atomic

    path.parent.mkdir(parents=True, exist_ok=True)
    write_bytes_atomic(path, index_bytes(kind, metas, extra))


def read_parquet(path: Path, columns: list[str] | None = None) -> Any:
    """A parquet file of the dataset as a pyarrow Table; a missing, truncated or damaged file,
    or one without the columns asked for, is a one-line VtsError naming it."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from ..jsonio import regular_file

    regular_file(path, "index")
    try:
        return pq.read_table(path, columns=columns)
    except (pa.ArrowException, OSError, KeyError, ValueError) as e:
        text = str(e).strip().splitlines()[0][:150] if str(e).strip() else type(e).__name__
        raise VtsError(f"not a readable parquet file ({text})", path) from None


def read_index(path: Path, kind: str) -> list[SampleMeta]:
    """Read one kind's index back into SampleMeta rows; one-line VtsError when unreadable."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from ..jsonio import regular_file

    regular_file(path, "index")  # a folder, a FIFO or a device is said as such
    try:
        table = pq.read_table(path)
    except (pa.ArrowException, OSError) as e:
        raise VtsError(f"not a readable parquet file ({e})", path) from None
    if index_schema_of(table.schema, kind) is None:
        have = ", ".join(f"{f.name}: {f.type}" for f in table.schema)
        raise VtsError(f"columns differ from the {kind} index schema (found {have})", path)
    try:
        return [SampleMeta.from_row(r, kind) for r in table.to_pylist()]
    except (TypeError, ValueError) as e:
        raise VtsError(f"bad row ({e})", path) from None
