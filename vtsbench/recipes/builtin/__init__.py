"""Reference recipes of vtsbench, registered under the entry-point group `vtsbench.recipes`
(see docs/recipes.md). Each module defines `RECIPE`."""
