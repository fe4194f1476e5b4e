# accum: set-up, demo, tests and benchmarks. Only python3 (>= 3.10) is needed.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
SAMPLE := sample_data/sim_box.mcap
DEMO := out/demo

.PHONY: demo test bench figures sample suite clean

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
	$(BIN)/accum accumulate $(SAMPLE) -o $(DEMO)/model.json -o $(DEMO)/model.ply --rrd $(DEMO)/run.rrd \
		--png $(DEMO)/model.png --panel $(DEMO)/panel.png --truth sample_data/sim_box.truth.json
	@echo
	@echo "Results in $(DEMO)/:"
	@echo "  model.json, model.ply   the accumulated model (open the .ply in MeshLab or Open3D)"
	@echo "  run.rrd                 the run in Rerun:  $(BIN)/rerun $(DEMO)/run.rrd"
	@echo "  model.png, panel.png    pictures of the model and of the last frame"
	@echo "Next: $(BIN)/accum --help"

# Both cores (pytest-xdist; a test file's tests stay on one worker, so its module fixtures are built
# once): 2.5 minutes where one process took 4 (2026-12-07, 2 cores). At most 4 workers: each holds
# its own copy of the session's recordings and libraries (up to 0.84 GB measured, 2026-12-07).
test: $(VENV)/.installed-test
	$(BIN)/python -m pytest -n auto --maxprocesses 4 --dist loadfile

bench: $(VENV)/.installed-test
	OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 $(BIN)/python benchmarks/run.py

# Accuracy figures of extract, accumulate and track against ground truth (a few minutes).
figures: $(VENV)/.installed
	ACCUM=$(BIN)/accum bash benchmarks/figures.sh

# Regenerate the committed synthetic sample (deterministic: the same images, poses and truth for the same
# seed; the committed file predates one metadata field, so its bytes differ by that).
sample: $(VENV)/.installed
	$(BIN)/accum simulate -o $(SAMPLE) --scene classic --count 36 --seed 0 --shape box --encoding jpeg

clean:
	rm -rf $(VENV) out .pytest_cache

# The scoreboard of extraction and accumulation over simulated, independent and real recordings.
suite: $(VENV)/.installed
	OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 $(BIN)/python benchmarks/suite.py
	OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 $(BIN)/python benchmarks/track_suite.py

# Are the extracted segments' depth and direction sigmas honest? Errors against truth per sigma bin (after make suite), single-frame direction errors by how pieces were triangulated, and the 2D lines' angle errors by span (devset).
.PHONY: uncertainty
uncertainty: $(VENV)/.installed
	$(BIN)/python benchmarks/uncertainty.py
	$(BIN)/python benchmarks/piece_directions.py

# --motion tracked on noisy gripper poses against the exact-pose model (random scenes, a few minutes).
.PHONY: motion
motion: $(VENV)/.installed
	OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 $(BIN)/python benchmarks/motion_suite.py

# Mutated recordings through info, extraction and accumulation (10,000 inputs by default; bounded:
# make fuzz FUZZ_ARGS="--count 500" or FUZZ_ARGS="--seconds 120"). Failing inputs go to out/fuzz_crashes/.
.PHONY: fuzz
fuzz: $(VENV)/.installed-test
	OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 $(BIN)/python benchmarks/fuzz.py $(FUZZ_ARGS)
