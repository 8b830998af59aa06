# The two commands of the README. Each creates .venv and installs derods into it
# when needed, so a fresh machine needs only Python >= 3.10 and pip.
PYTHON ?= python3
VENV := .venv
STAMP := $(VENV)/.installed

.PHONY: demo core-demo test bench report clean

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

# The sample comparison report (docs/report/): accuracy sweeps, stability map and extreme
# cases for derods and MuJoCo's native flexcomp. Resumes where a previous run stopped.
report: $(STAMP)
	$(VENV)/bin/python -m derods compare --full --workers 2 --results docs/report/results.jsonl --report-dir docs/report

clean:
	rm -rf $(VENV) build *.egg-info
