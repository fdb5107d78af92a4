"""The built-in recipes' old package: each module re-exports `vtsbench.recipes.builtin.NAME`,
so the entry points `vtsbench.recipes_builtin.NAME:RECIPE` registered in pyproject.toml (and
installed metadata written from it) keep working."""
