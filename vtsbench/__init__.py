"""vtsbench."""
