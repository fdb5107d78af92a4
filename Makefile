# Two commands: `make demo` and `make test`. Both create .venv and install what they need.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
DEMO   ?= demo-data
SEED   ?= 0
WORKERS ?= 2

.PHONY: demo v2 results results-v2 test lint bench clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

$(VENV)/.installed: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --disable-pip-version-check -q -e '.[dev,torch]'
	touch $@

## demo: the main job on the synthetic sensor, the demo profile of benchmark v2 (the same
## generator and sensor, fewer sequences): simulate + calibrate + build (`vtsbench benchmark
## v2-demo`) -> check -> verify -> load -> train the small baselines -> predict -> eval ->
## leaderboard (the training part trains two runs side by side, one torch thread each; see
## docs/results.md for its time)
demo: $(VENV)/.installed
	$(BIN)/vtsbench benchmark v2-demo $(DEMO) --seed $(SEED) --workers $(WORKERS) --overwrite --quiet
	$(BIN)/vtsbench check $(DEMO)/recordings
	$(BIN)/vtsbench preview $(DEMO)/recordings --out $(DEMO)/preview.png
	$(BIN)/vtsbench verify $(DEMO)/dataset
	$(BIN)/vtsbench info $(DEMO)/dataset
	$(BIN)/python -c "import vtsbench; ds = vtsbench.load('$(DEMO)/dataset'); \
		test = ds.split('unseen_objects', 'test'); s = test[0]; \
		print(f'loaded {len(ds.static)} static and {len(ds.slip)} slip samples; unseen_objects/test: {len(test)} sequences;', \
		s['sample_id'], s['rgb'].shape, s['depth'].shape, f\"max depth {s['depth'].max():.3f} mm\")"
	$(BIN)/python benchmarks/results.py --dataset $(DEMO)/dataset --runs $(DEMO)/runs \
		--leaderboards $(DEMO)/leaderboards --out $(DEMO)/results.md --retrain
	@echo "demo done: recordings in $(DEMO)/recordings (contact sheet $(DEMO)/preview.png), calibration report in $(DEMO)/recordings/calibration.safetensors.report/, dataset in $(DEMO)/dataset, runs in $(DEMO)/runs, leaderboards in $(DEMO)/leaderboards, results table in $(DEMO)/results.md"

## v2: benchmark v2 (3,600 sequences, 3,000 static frames at 240x320; about 2 GB dataset and
## 9 GB recordings) in $(V2), and results-v2 its published figures: docs/results.md and
## leaderboards/. With OTHER=results.json (--summary of the same runs on a dataset of another
## seed, e.g. `vtsbench benchmark v2 v2-seed7 --seed 7` and --splits unseen_objects), its table.
V2 ?= v2-data
v2: $(VENV)/.installed
	$(BIN)/vtsbench benchmark v2 $(V2) --workers $(WORKERS)

## With OCTOPI=folder of the octopi GelSight Mini videos, also ResNet on that real data.
results-v2: $(VENV)/.installed
	test -f $(V2)/dataset/meta/info.json || $(MAKE) v2
	$(if $(OCTOPI),test -f $(V2)/octopi-dataset/meta/info.json || ( \
		$(BIN)/vtsbench manifest $(OCTOPI) --pattern '{object}_{session:d}.mov' --kind static \
			--stride 20 --sensor gelsight-mini --out $(V2)/octopi --overwrite && \
		$(BIN)/vtsbench build $(V2)/octopi $(V2)/octopi-dataset --no-depth \
			--workers $(WORKERS) --overwrite ))
	$(BIN)/python benchmarks/results.py --dataset $(V2)/dataset --runs $(V2)/runs \
		--leaderboards leaderboards --out docs/results.md --profile v2 \
		--summary $(V2)/results.json $(if $(OCTOPI),--octopi $(V2)/octopi-dataset) \
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

## test: install the dev extras and run the test suite on both cores (one OpenBLAS thread in
## each of the two test workers: with a BLAS thread pool in each, a test once sat 7 minutes in
## one sgemm, its main thread spinning while the pool's threads slept)
test: $(VENV)/.installed
	OPENBLAS_NUM_THREADS=1 $(BIN)/python -m pytest -q -n 2

lint: $(VENV)/.installed
	$(BIN)/ruff check vtsbench tests benchmarks

bench: $(VENV)/.installed
	$(BIN)/python benchmarks/simulator.py

clean:
	rm -rf $(VENV) $(DEMO) .pytest_cache
