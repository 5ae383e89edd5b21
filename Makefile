# Developer tasks for rehabbot. `make test` works on a fresh machine with Python 3.11
# and the system packages installed by .ci/run (EGL/OSMesa for offscreen rendering,
# Xvfb for the interactive viewer test).

PYTHON_BOOTSTRAP ?= $(shell command -v python3.11 >/dev/null 2>&1 && echo python3.11 || echo python3)
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
export MUJOCO_GL ?= egl

.PHONY: venv test test-fast demo docs docs-check lint bench images clean distclean

venv: $(STAMP)

$(VENV): $(STAMP)

# Re-install whenever the package metadata changes.
$(STAMP): pyproject.toml rehabbot/common/version.py
	test -x $(PY) || $(PYTHON_BOOTSTRAP) -m venv $(VENV)
	$(PY) -m pip install --upgrade pip
	$(PY) -m pip install -e ".[all]"
	touch $(STAMP)

# Without a display, the suite runs under Xvfb so that the `human` render mode (MuJoCo's
# viewer) is tested too.
XVFB := $(if $(DISPLAY),,$(shell command -v xvfb-run >/dev/null 2>&1 && echo xvfb-run -a))

# The full suite (CI runs this), on every core (pytest-xdist, at most 4 workers). `make
# test-fast` (or plain `pytest`, in one process) runs the fast selection: every test not marked
# slow, in under two minutes. The full suite reports each failure's reason and its 30 slowest
# tests (-rf --durations=30), so that a slow or failing test is named in CI's log. Work
# stealing (--dist worksteal) keeps a worker that drew a long batched replay from holding up
# the end of the run.
PARALLEL := -n auto --maxprocesses 4 --dist worksteal

# Tests marked realtime run a robot's 1 kHz control loop against franka-sim (the libfranka
# protocol's simulator, in .venv-franka-sim: tools/franka-sim-venv.sh); they run after the rest,
# in one process, so that no other test competes with the loop for the CPU. franka-sim steps
# its physics against the wall clock in a process of its own: a machine that stalls it for
# milliseconds can fault a motion that real time would not, so a realtime test that fails runs
# up to twice more (pytest-rerunfailures), and the log names every rerun (-rR).
test: $(STAMP)
	MUJOCO_GL=$(MUJOCO_GL) $(XVFB) $(PY) -m pytest -q --full $(PARALLEL) -rf --durations=30 \
	  -m "not realtime"
	$(PY) -m pytest -q --full -rfRxX -m realtime -p no:xdist --reruns 2 --reruns-delay 2

test-fast: $(STAMP)
	MUJOCO_GL=$(MUJOCO_GL) $(XVFB) $(PY) -m pytest -q $(PARALLEL)

demo: $(STAMP)
	MUJOCO_GL=$(MUJOCO_GL) $(VENV)/bin/rehabbot demo --out runs/demo

# The documentation site (Sphinx, MyST, Furo) into docs/_build/html, in strict mode: a warning,
# a broken cross-reference (-n) or a tutorial that fails to execute fails the build; every
# problem is reported before it stops (--keep-going). It is built in a venv of its own,
# .venv-docs, with `.[docs]` alone: so the build proves that extra is enough (an API page that
# needs another extra's library fails it: docs/_ext/optional_imports.py).
DOCS_VENV := .venv-docs
DOCS_PY := $(DOCS_VENV)/bin/python
DOCS_STAMP := $(DOCS_VENV)/.installed

$(DOCS_STAMP): pyproject.toml rehabbot/common/version.py
	test -x $(DOCS_PY) || $(PYTHON_BOOTSTRAP) -m venv $(DOCS_VENV)
	$(DOCS_PY) -m pip install --upgrade pip
	$(DOCS_PY) -m pip install -e ".[docs]"
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	MUJOCO_GL=$(MUJOCO_GL) $(DOCS_PY) -m sphinx -W --keep-going -n -b html docs docs/_build/html

# The built site, page by page, in headless Chromium (Debian's chromium and chromium-driver):
# tables shown as text, reprs instead of figures, content wider than the page, clipped code or
# output, images that do not load (docs/_ext/site_check.py). Run `make docs` first.
docs-check: $(DOCS_STAMP)
	$(DOCS_PY) docs/_ext/site_check.py docs/_build/html

lint: $(STAMP)
	$(VENV)/bin/ruff check .

# The performance pages of docs/results/ (ratios against a baseline measured in the same run),
# written by the commands they record.
bench: $(STAMP)
	$(PY) benchmarks/performance/physics_throughput.py --robots ur5e fr3 \
	  --page docs/results/physics-throughput
	$(PY) benchmarks/performance/step_throughput.py --page docs/results/step-throughput

# The README's scene pictures, rendered by our own code.
images: $(STAMP)
	for preset in upper_right upper_left upper_bilateral hip knee; do \
	  MUJOCO_GL=$(MUJOCO_GL) $(VENV)/bin/rehabbot snapshot $$preset --out docs/images/$$preset.png \
	    --width 640 --height 480 || exit 1; \
	done
	for preset in hip knee upper_right; do \
	  MUJOCO_GL=$(MUJOCO_GL) $(VENV)/bin/rehabbot snapshot $$preset --patient-model myo \
	    --out docs/images/$$preset-myo.png --width 640 --height 480 || exit 1; \
	done

# Build outputs and caches; keeps the virtual environment and runs/ (experiment results).
clean:
	rm -rf build dist *.egg-info .pytest_cache .ruff_cache .hypothesis docs/_build docs/_generated
	find . -path ./$(VENV) -prune -o -name __pycache__ -type d -prune -exec rm -rf {} +

# Everything `clean` removes, plus the virtual environments.
distclean: clean
	rm -rf $(VENV) $(DOCS_VENV)
