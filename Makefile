# Two commands: `make demo` and `make test`. Both create .venv and install what they need.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
DEMO   ?= demo-data
SEED   ?= 0
WORKERS ?= 2
STATIC ?= 300
SEQUENCES ?= 360

.PHONY: demo results results-demo test lint bench clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

$(VENV)/.installed: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --disable-pip-version-check -q -e '.[dev,torch]'
	touch $@

## demo: the main job on the synthetic sensor: simulate -> check -> calibrate -> build -> verify ->
## load -> train the small baselines -> predict -> eval -> leaderboard (the training part trains two
## runs side by side, one torch thread each; see docs/results.md for its time)
demo: $(VENV)/.installed
	$(BIN)/vtsbench simulate $(DEMO)/recordings --seed $(SEED) --static $(STATIC) \
		--sequences $(SEQUENCES) --presses 20 --workers $(WORKERS) --overwrite --quiet
	$(BIN)/vtsbench check $(DEMO)/recordings
	$(BIN)/vtsbench preview $(DEMO)/recordings --out $(DEMO)/preview.png
	$(BIN)/vtsbench calibrate $(DEMO)/recordings --out $(DEMO)/recordings/calibration.safetensors \
		--method lut --holdout 4
	$(BIN)/vtsbench build $(DEMO)/recordings $(DEMO)/dataset --workers $(WORKERS) --overwrite
	$(BIN)/vtsbench verify $(DEMO)/dataset
	$(BIN)/vtsbench info $(DEMO)/dataset
	$(BIN)/python -c "import vtsbench; ds = vtsbench.load('$(DEMO)/dataset'); \
		test = ds.split('unseen_objects', 'test'); s = test[0]; \
		print(f'loaded {len(ds.static)} static and {len(ds.slip)} slip samples; unseen_objects/test: {len(test)} sequences;', \
		s['sample_id'], s['rgb'].shape, s['depth'].shape, f\"max depth {s['depth'].max():.3f} mm\")"
	$(BIN)/python benchmarks/results.py --dataset $(DEMO)/dataset --runs $(DEMO)/runs \
		--leaderboards $(DEMO)/leaderboards --out $(DEMO)/results.md --retrain
	@echo "demo done: recordings in $(DEMO)/recordings (contact sheet $(DEMO)/preview.png), calibration report in $(DEMO)/recordings/calibration.safetensors.report/, dataset in $(DEMO)/dataset, runs in $(DEMO)/runs, leaderboards in $(DEMO)/leaderboards, results table in $(DEMO)/results.md"

## results-demo: the published demo-profile figures: the demo's dataset -> docs/results.md and
## leaderboards/; with OCTOPI=folder of the octopi GelSight Mini videos, also ResNet on that data;
## with OTHER=results.json (--summary of the same profile on a dataset of another seed), its table
results-demo: $(VENV)/.installed
	test -f $(DEMO)/dataset/meta/info.json || $(MAKE) demo
	$(if $(OCTOPI),test -f $(DEMO)/octopi-dataset/meta/info.json || ( \
		$(BIN)/vtsbench manifest $(OCTOPI) --pattern '{object}_{session:d}.mov' --kind static \
			--stride 20 --sensor gelsight-mini --out $(DEMO)/octopi --overwrite && \
		$(BIN)/vtsbench build $(DEMO)/octopi $(DEMO)/octopi-dataset --no-depth \
			--workers $(WORKERS) --overwrite ))
	$(BIN)/python benchmarks/results.py --dataset $(DEMO)/dataset --runs $(DEMO)/runs \
		--leaderboards leaderboards --out docs/results.md --profile demo \
		--summary $(DEMO)/results.json $(if $(OCTOPI),--octopi $(DEMO)/octopi-dataset) \
		$(if $(OTHER),--other $(OTHER))

## results: the paper-scale profile: ~8,000 sequences and ~19,000 static frames simulated, the
## paper's models (TimeSformer-base 224, ResNet-50 224) on a GPU when there is one, else on the
## CPU with fewer steps (the page says which). WEIGHTS=folder of the SSv2 TimeSformer weights
## (optional). Disk: about 170 GB at full counts (recordings 100, dataset 65); set
## PAPER_STATIC / PAPER_SEQUENCES lower to fit a smaller disk.
PAPER ?= paper-data
PAPER_STATIC ?= 19000
PAPER_SEQUENCES ?= 8000
results: $(VENV)/.installed
	test -f $(PAPER)/dataset/meta/info.json || ( \
		$(BIN)/vtsbench simulate $(PAPER)/recordings --seed $(SEED) --static $(PAPER_STATIC) \
			--sequences $(PAPER_SEQUENCES) --presses 20 --workers $(WORKERS) --overwrite --quiet && \
		$(BIN)/vtsbench calibrate $(PAPER)/recordings \
			--out $(PAPER)/recordings/calibration.safetensors --method lut --holdout 4 && \
		$(BIN)/vtsbench build $(PAPER)/recordings $(PAPER)/dataset --workers $(WORKERS) --overwrite )
	$(BIN)/python benchmarks/results.py --dataset $(PAPER)/dataset --runs $(PAPER)/runs \
		--leaderboards leaderboards --out docs/results.md --profile results \
		--summary $(PAPER)/results.json $(if $(WEIGHTS),--pretrained $(WEIGHTS))

## test: install the dev extras and run the test suite on both cores
test: $(VENV)/.installed
	$(BIN)/python -m pytest -q -n 2

lint: $(VENV)/.installed
	$(BIN)/ruff check vtsbench tests benchmarks

bench: $(VENV)/.installed
	$(BIN)/python benchmarks/simulator.py

clean:
	rm -rf $(VENV) $(DEMO) .pytest_cache
