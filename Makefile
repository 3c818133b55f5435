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

demo: install
	mkdir -p out
	$(VENV)/bin/lensopt trace specs/cooke_triplet.toml
	$(VENV)/bin/lensopt trace specs/cooke_triplet.toml --json > out/cooke_triplet_trace.json
	$(VENV)/bin/lensopt plot layout specs/cooke_triplet.toml -o out/cooke_triplet_layout.png
	$(VENV)/bin/lensopt plot fans specs/cooke_triplet.toml -o out/cooke_triplet_fans.png
	$(VENV)/bin/lensopt plot spots specs/cooke_triplet.toml -o out/cooke_triplet_spots.png
	$(VENV)/bin/lensopt plot psf specs/cooke_triplet.toml -o out/cooke_triplet_psf.png --pitch-um 2 --sqrt
	$(VENV)/bin/lensopt simulate specs/cooke_triplet.toml examples/images/coffee.png --region corner \
		-o out/coffee_cooke_corner.png

test: install
	$(PY) -m pytest -q

lint: install
	$(VENV)/bin/ruff check lensopt tests benchmarks

clean:
	rm -rf $(VENV) out
