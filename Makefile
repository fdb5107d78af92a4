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

## demo: simulate a recordings folder on the synthetic sensor, check it, write a preview
demo: $(VENV)/.installed
	$(BIN)/vtsbench simulate $(DEMO)/recordings --seed $(SEED) --static 30 --sequences 30 \
		--presses 20 --workers $(WORKERS) --overwrite
	$(BIN)/vtsbench check $(DEMO)/recordings
	$(BIN)/vtsbench preview $(DEMO)/recordings --out $(DEMO)/preview.png
	@echo "demo done: recordings in $(DEMO)/recordings, contact sheet in $(DEMO)/preview.png"

## test: install the dev extras and run the test suite on both cores
test: $(VENV)/.installed
	$(BIN)/python -m pytest -q -n 2

lint: $(VENV)/.installed
	$(BIN)/ruff check vtsbench tests benchmarks

bench: $(VENV)/.installed
	$(BIN)/python benchmarks/simulator.py

clean:
	rm -rf $(VENV) $(DEMO) .pytest_cache
