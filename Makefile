# Two commands: `make demo` and `make test`. Both create .venv and install what they need.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
DEMO   ?= demo-data
SEED   ?= 0
WORKERS ?= 2

.PHONY: demo test lint bench clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

$(VENV)/.installed: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --disable-pip-version-check -q -e '.[dev,torch]'
	touch $@

## demo: the main job on the synthetic sensor: simulate -> check -> calibrate -> build -> verify -> load
demo: $(VENV)/.installed
	$(BIN)/vtsbench simulate $(DEMO)/recordings --seed $(SEED) --static 30 --sequences 30 \
		--presses 20 --workers $(WORKERS) --overwrite
	$(BIN)/vtsbench check $(DEMO)/recordings
	$(BIN)/vtsbench preview $(DEMO)/recordings --out $(DEMO)/preview.png
	$(BIN)/vtsbench calibrate $(DEMO)/recordings --out $(DEMO)/recordings/calibration.safetensors \
		--method poly --holdout 4
	$(BIN)/vtsbench build $(DEMO)/recordings $(DEMO)/dataset --workers $(WORKERS) --overwrite
	$(BIN)/vtsbench verify $(DEMO)/dataset
	$(BIN)/vtsbench info $(DEMO)/dataset
	$(BIN)/python -c "import vtsbench; ds = vtsbench.load('$(DEMO)/dataset'); \
		test = ds.split('unseen_objects', 'test'); s = test[0]; \
		print(f'loaded {len(ds.static)} static and {len(ds.slip)} slip samples; unseen_objects/test: {len(test)} sequences;', \
		s['sample_id'], s['rgb'].shape, s['depth'].shape, f\"max depth {s['depth'].max():.3f} mm\")"
	@echo "demo done: recordings in $(DEMO)/recordings (contact sheet $(DEMO)/preview.png), calibration report in $(DEMO)/recordings/calibration.safetensors.report/, dataset in $(DEMO)/dataset"

## test: install the dev extras and run the test suite on both cores
test: $(VENV)/.installed
	$(BIN)/python -m pytest -q -n 2

lint: $(VENV)/.installed
	$(BIN)/ruff check vtsbench tests benchmarks

bench: $(VENV)/.installed
	$(BIN)/python benchmarks/simulator.py

clean:
	rm -rf $(VENV) $(DEMO) .pytest_cache
