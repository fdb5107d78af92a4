"""Commands on a built dataset: `vtsbench info` (info), `verify` (verify), `export-hf` (hub,
with hub_layout, hub_rows and hub_write) and `push` (push)."""
