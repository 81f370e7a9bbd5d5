# Entry points for a fresh machine: `make demo`, `make lint` and `make test` (each creates .venv on first use).

PYTHON3 ?= python3
VENV := .venv
PY := $(VENV)/bin/python
# Written after a successful install; any change to what it depends on reinstalls.
STAMP := $(VENV)/.installed
PACKAGES := src/formation_msgs_py src/formation_agent src/formation_sim
PACKAGING := $(foreach p,$(PACKAGES),$(p)/setup.py $(p)/setup.cfg $(p)/package.xml)
# The compiled core (docs/COMPILED_CORE.md) is built by formation_agent's install: a change to its
# source reinstalls, which rebuilds it.
COMPILED := src/formation_agent/formation_agent/core/_fastcore.c

# xdist workers; loadgroup keeps tests marked xdist_group(name) on one worker (per-test timeout:
# pytest.ini). Override e.g. `make test PYTEST_ARGS='-n 0 -k recorder'`.
PYTEST_ARGS ?= -n auto --dist loadgroup

DEMO_DIR = runs/demo

.PHONY: venv lint test test-pure demo bench docs clean distclean

venv: $(STAMP)

$(STAMP): requirements.txt requirements-dev.txt $(PACKAGING) $(COMPILED)
	test -x $(PY) || $(PYTHON3) -m venv $(VENV)
	$(PY) -m pip install --disable-pip-version-check -q -r requirements-dev.txt
	# --no-deps: every dependency is pinned in requirements*.txt; the three packages depend on
	# each other by import, not through PyPI.
	$(PY) -m pip install --disable-pip-version-check -q --no-deps $(foreach p,$(PACKAGES),-e $(p))
	touch $(STAMP)

# ruff with pyproject.toml's rule set and format. To fix what they report:
# `.venv/bin/ruff format . && .venv/bin/ruff check --fix .`. Then mypy (scripts/typecheck.py):
# strict on formation_agent.core and the contracts, no error beyond scripts/mypy_baseline.txt.
lint: venv
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(PY) scripts/typecheck.py

# pytest exits 5 when it collects no test: not a failure of the code, so report it and pass.
test: venv
	@rc=0; $(PY) -m pytest $(PYTEST_ARGS) || rc=$$?; \
	if [ $$rc -eq 5 ]; then echo "pytest collected no tests (exit 5)"; rc=0; fi; \
	exit $$rc

# The paper's single-integrator example distributed over ROS 2 nodes and recorded, then the
# figures and the report recomputed from the bag alone. --force: each demo replaces the last one
# in runs/demo (and only that folder), so `make demo` can be run again and again.
# The search's and the engine's tests again on the pure-Python path (FORMATION_PURE_PYTHON=1),
# which a machine without the compiled core runs; `make test` runs them compiled.
PURE_TESTS := test_eta.py test_crossing.py test_closed_form.py test_speed_scale.py
test-pure: venv
	FORMATION_PURE_PYTHON=1 $(PY) -m pytest $(PYTEST_ARGS) $(addprefix tests/formation_agent/core/,$(PURE_TESTS)) \
	  $(addprefix tests/formation_sim/sim/,test_engine.py test_engine_rounding_floor.py test_engine_speed_scale.py)

demo: venv
	$(VENV)/bin/formation run paper_single --horizon 10 --out $(DEMO_DIR) --force
	$(VENV)/bin/formation analyze $(DEMO_DIR)

# The docs site (docs/index.md and every page it lists, the API reference from the docstrings) into
# docs/_build/html; -W: a warning (a broken link or reference, a page left out) fails the build.
DOCS_STAMP := $(VENV)/.docs-installed

$(DOCS_STAMP): requirements-docs.txt $(STAMP)
	$(PY) -m pip install --disable-pip-version-check -q -r requirements-docs.txt
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	$(PY) -m sphinx -W --keep-going -q -b html docs docs/_build/html
	@echo "docs: docs/_build/html/index.html"

bench: venv
	@if [ -f benchmarks/run.py ]; then $(PY) benchmarks/run.py; else echo "no benchmarks yet (benchmarks/run.py is missing)"; fi

clean:
	rm -rf runs docs/_build ros2_ws/build ros2_ws/install ros2_ws/log build install log .pytest_cache .ruff_cache .mypy_cache
	find src tests -name __pycache__ -type d -prune -exec rm -rf {} +
	find src -name '*.egg-info' -type d -prune -exec rm -rf {} +

distclean: clean
	rm -rf $(VENV)
