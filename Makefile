# accum: set-up, demo, tests and benchmarks. Only python3 (>= 3.10) is needed.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
SAMPLE := sample_data/sim_box.mcap
DEMO := out/demo

.PHONY: demo test bench sample clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

$(VENV)/.installed: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e .
	@touch $@

$(VENV)/.installed-test: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[test]'
	@touch $@ $(VENV)/.installed

demo: $(VENV)/.installed
	@mkdir -p $(DEMO)
	$(BIN)/accum info $(SAMPLE)
	@echo
	@echo "accum is installed in $(VENV); the recording summary above is of $(SAMPLE)"

test: $(VENV)/.installed-test
	$(BIN)/python -m pytest

bench: $(VENV)/.installed-test
	OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 $(BIN)/python benchmarks/run.py

# Regenerate the committed synthetic sample (deterministic: same bytes for the same seed).
sample: $(VENV)/.installed
	$(BIN)/accum simulate -o $(SAMPLE) --frames 36 --seed 0 --shape box --encoding jpeg

clean:
	rm -rf $(VENV) out .pytest_cache
