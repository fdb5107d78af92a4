"""The vtsbench dataset, in the stages of its data flow (each imports only earlier ones):
format (the on-disk contract), splits (split schemes and the leak check), read (`load`,
views, adapters), build (`vtsbench build`) and tools (`info`, `verify`, `export-hf`, `push`)."""
