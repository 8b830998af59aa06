# The two commands of the README. Each creates .venv and installs derods into it
# when needed, so a fresh machine needs only Python >= 3.10 and pip.
PYTHON ?= python3
VENV := .venv
STAMP := $(VENV)/.installed

.PHONY: demo core-demo test bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/python -m pip install --quiet --upgrade pip
	$(VENV)/bin/python -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

# The main job: drop rods onto a rigid scene and write out/drop.mp4 (headless).
demo: $(STAMP)
	mkdir -p out
	$(VENV)/bin/python -m derods drop --out out/drop.mp4

core-demo: $(STAMP)
	$(VENV)/bin/python -m derods demo

test: $(STAMP)
	$(VENV)/bin/python -m pytest -q

bench: $(STAMP)
	$(VENV)/bin/python benchmarks/bench_core.py

clean:
	rm -rf $(VENV) build *.egg-info
