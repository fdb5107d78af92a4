"""The on-disk contract of a built dataset: its paths and constants (layout), typed records
(records, info), the index (index), the Zarr arrays (arrays) and provenance; no I/O policy."""
