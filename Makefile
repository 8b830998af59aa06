# The two commands of the README. Each creates .venv and installs derods into it
# when needed, so a fresh machine needs only Python >= 3.10 and pip.
PYTHON ?= python3
VENV := .venv
STAMP := $(VENV)/.installed
STAMPDOCS := $(VENV)/.installed-docs
# MuJoCo 4.0 removed the cable plugin: the cable backend runs in a second environment.
VENV317 := .venv317
STAMP317 := $(VENV317)/.installed
# PyElastica, a peer rod simulator, runs in a third environment of its own.
VENVEL := .venv-elastica
STAMPEL := $(VENVEL)/.installed

.PHONY: demo core-demo test docs test317 test-elastica venv317 venv-elastica bench report cosseratbench docs-images docs-editor clean clean-cache

$(STAMP): pyproject.toml
	@echo "make: creating $(VENV) and installing derods with numpy, scipy, mujoco, numba (a minute or two)"
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/python -m pip install --quiet --upgrade pip
	$(VENV)/bin/python -m pip install --progress-bar off -e '.[dev,ui,cosseratbench,dask]'
	@echo "make: compiling derods' kernels once (about a minute of CPU; later runs load them in a second)"
	$(VENV)/bin/python -c "from derods.sim import warmup; warmup.prepare()"
	touch $(STAMP)

# The main job: drop rods onto a rigid scene and write out/drop.mp4 (headless).
demo: $(STAMP)
	mkdir -p out
	$(VENV)/bin/python -m derods drop --out out/drop.mp4

core-demo: $(STAMP)
	$(VENV)/bin/python -m derods demo

test: $(STAMP)
	$(VENV)/bin/python -m pytest -q

$(STAMPDOCS): $(STAMP)
	$(VENV)/bin/python -m pip install --progress-bar off -e '.[docs]'
	touch $(STAMPDOCS)

# The documentation site (docs/, mkdocs.yml) with its API reference generated from the
# docstrings, built into site/. Strict: a broken reference, a missing page or a bad link
# fails the build.
docs: $(STAMPDOCS)
	$(VENV)/bin/python -m mkdocs build --strict

bench: $(STAMP)
	$(VENV)/bin/python benchmarks/bench_core.py

$(STAMP317): pyproject.toml
	@echo "make: creating $(VENV317) with mujoco 3.17.0 (the cable plugin) and derods"
	$(PYTHON) -m venv $(VENV317)
	$(VENV317)/bin/python -m pip install --quiet --upgrade pip
	$(VENV317)/bin/python -m pip install --progress-bar off "mujoco==3.17.0" -e '.[dev,cosseratbench]'
	touch $(STAMP317)

venv317: $(STAMP317)

$(STAMPEL): pyproject.toml
	@echo "make: creating $(VENVEL) with pyelastica 1.0.0 and derods (PyElastica compiles ~1 min of numba on first use)"
	$(PYTHON) -m venv $(VENVEL)
	$(VENVEL)/bin/python -m pip install --quiet --upgrade pip
	$(VENVEL)/bin/python -m pip install --progress-bar off "pyelastica==1.0.0" -e '.[dev,cosseratbench]'
	touch $(STAMPEL)

venv-elastica: $(STAMPEL)

# Quick checks of the PyElastica backend in its environment.
test-elastica: $(STAMPEL)
	$(VENVEL)/bin/python -m pytest -q tests_elastica

# Quick checks in MuJoCo 3.17: derods, the flexcomp and the cable backend.
test317: $(STAMP317)
	$(VENV317)/bin/python -m pytest -q tests317

# The sample comparison report (docs/report/): accuracy sweeps, stability map, extreme
# cases and hair at scale for derods, MuJoCo's native flexcomp and cable, and PyElastica. Resumes where a previous
# run stopped.
report: $(STAMP) $(STAMP317) $(STAMPEL)
	$(VENV317)/bin/python -m derods compare --full --backends cable --workers 2 \
		--results docs/report/results.jsonl --report-dir docs/report
	$(VENVEL)/bin/python -m derods compare --full --backends elastica --workers 2 \
		--results docs/report/results.jsonl --report-dir docs/report
	$(VENV)/bin/python benchmarks/bench_hair.py --append-to docs/report/results.jsonl
	$(VENV)/bin/python -m derods compare --full --workers 2 --results docs/report/results.jsonl --report-dir docs/report

# cosseratbench, an independent rod benchmark suite: every experiment at its default
# resolution, and at half and twice it for the cantilever, catenary and twist, on derods
# (MuJoCo 4), MuJoCo's cable (3.17) and PyElastica, one run at a time; then the report's
# section docs/report/cosseratbench.md. Saved runs whose inputs have not changed are reused
# (the suite's own rule); delete $(CB_RESULTS) to measure everything again.
CB_RESULTS := results/cosseratbench
CB_VARIED := cantilever catenary twist
cosseratbench: $(STAMP) $(STAMP317) $(STAMPEL)
	$(VENV)/bin/cosseratbench run -s derods -o $(CB_RESULTS)
	$(VENV)/bin/cosseratbench run $(CB_VARIED) -s derods -v resolution -o $(CB_RESULTS)
	$(VENV317)/bin/cosseratbench run -s mujoco -o $(CB_RESULTS)
	$(VENV317)/bin/cosseratbench run $(CB_VARIED) -s mujoco -v resolution -o $(CB_RESULTS)
	$(VENVEL)/bin/cosseratbench run -s pyelastica -o $(CB_RESULTS)
	$(VENVEL)/bin/cosseratbench run $(CB_VARIED) -s pyelastica -v resolution -o $(CB_RESULTS)
	$(VENV)/bin/python benchmarks/cosseratbench_report.py --results $(CB_RESULTS)

# The README's pictures of the scenes and of the render quality.
docs-images: $(STAMP)
	$(VENV)/bin/python docs/images.py

# The README's screenshots of the browser editor (needs Debian's chromium).
docs-editor: $(STAMP)
	$(VENV)/bin/python docs/editor_images.py

# numba's on-disk cache is keyed per source file: clear it after editing a kernel that others call.
clean-cache:
	find derods -name __pycache__ -type d -prune -exec rm -rf {} +

clean: clean-cache
	rm -rf $(VENV) $(VENV317) $(VENVEL) build site *.egg-info
