"""The vtsbench dataset: index rows, sample and info records (schema), split schemes (splits)."""
