# lensopt: `make demo` and `make test` are all a fresh clone needs.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
TORCH_PIN := torch==2.13.0

.PHONY: install demo test lint clean

install: $(STAMP)

# The pinned CPU torch goes in first so that no dependency pulls a CUDA build.
$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q $(TORCH_PIN)
	$(PY) -m pip install -q -e '.[dev,oracle]'
	touch $(STAMP)

DEMO_SPEC := specs/cooke_triplet.toml
DEMO := out/cooke_triplet

demo: install
	mkdir -p out
	$(VENV)/bin/lensopt trace $(DEMO_SPEC)
	$(VENV)/bin/lensopt trace $(DEMO_SPEC) --json > $(DEMO)_trace.json.part && mv $(DEMO)_trace.json.part $(DEMO)_trace.json
	$(VENV)/bin/lensopt plot layout $(DEMO_SPEC) -o $(DEMO)_layout.png
	$(VENV)/bin/lensopt plot fans $(DEMO_SPEC) -o $(DEMO)_fans.png
	$(VENV)/bin/lensopt plot spots $(DEMO_SPEC) -o $(DEMO)_spots.png
	@echo "demo outputs: $(DEMO)_trace.json $(DEMO)_layout.png $(DEMO)_fans.png $(DEMO)_spots.png"

test: install
	$(PY) -m pytest -q

lint: install
	$(VENV)/bin/ruff check lensopt tests benchmarks

clean:
	rm -rf $(VENV) out
