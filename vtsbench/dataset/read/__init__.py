"""Reading a built dataset: where it lives and how its files are fetched (location, remote),
its Zarr groups (store), `load` and views (loader, view), and the numpy, PyTorch, Hugging Face
and matplotlib adapters (arrays, torch_dataset, hf, plot)."""
