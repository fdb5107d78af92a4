"""A recipe's config: its defaults updated by a JSON or TOML file, each key checked against
the default's type."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from vtsbench.errors import VtsError


def load_config(recipe: Any, path: str | Path | None) -> dict[str, Any]:
    """The recipe's default config updated by a JSON (or TOML) file; unknown keys are an error."""
    config = dict(recipe.default_config())
    if path is None:
        return config
    from vtsbench.jsonio import loads, read_bytes

    path = Path(path)
    data = read_bytes(path, "config file", 16 << 20)
    if path.suffix == ".toml":
        import tomllib

        try:
            given = tomllib.loads(data.decode("utf-8"))
        except (ValueError, RecursionError) as e:
            raise VtsError(f"config is not valid TOML ({str(e)[:100]})", path) from None
    else:
        given = loads(data, path, "config JSON")
    if not isinstance(given, dict):
        raise VtsError("config must be a mapping of option names to values", path)
    unknown = sorted(set(given) - set(config))
    if unknown:
        raise VtsError(f"unknown config keys {unknown} (known: {sorted(config)})", path)
    nullable = getattr(recipe, "nullable", frozenset())
    for key, value in given.items():
        want = config[key]
        ok = (isinstance(value, type(want)) or want is None
              or (value is None and key in nullable)
              or (isinstance(want, float) and isinstance(value, int)))
        if not ok or (isinstance(value, bool) and want is not None
                      and not isinstance(want, bool)) or (
                isinstance(value, float) and not math.isfinite(value)):
            raise VtsError(f"config key {key!r}: expected a {type(want).__name__} like "
                           f"{want!r}, got {value!r}", path)
    config.update(given)
    return config
