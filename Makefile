# Two commands on a fresh clone: `make generate` and `make test`.
PYTHON_SYS ?= python3
VENV := .venv
PY := $(VENV)/bin/python
# every robot description in robots/ (a user's robots/my_arm.yaml included)
ROBOTS := $(sort $(wildcard robots/*.yaml))

.PHONY: generate test bench report clean

$(VENV)/.installed: pyproject.toml
	@echo "Setting up $(VENV): installing KinDynGen and its pinned dependencies (first run only, about a minute)..."
	$(PYTHON_SYS) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	touch $@

generate: $(VENV)/.installed
	$(PY) -m kindyngen generate $(ROBOTS) --out generated

# the suite on every logical CPU ("-n auto" counts physical cores: one on a 2-vCPU runner with
# hyperthreads; PYTEST_XDIST_AUTO_NUM_WORKERS=N overrides); --dist loadfile keeps each test
# file on one worker, so its module fixtures (derivations, compiled libraries) are built once
test: $(VENV)/.installed
	$(PY) -m pytest -n logical --dist loadfile --durations=20

# the benchmarks' extra peers (pyproject's "bench" extra: CppADCodeGen's headers), not needed by `make test`
$(VENV)/.bench-installed: $(VENV)/.installed
	$(PY) -m pip install --quiet -e '.[test,bench]'
	touch $@

bench: $(VENV)/.bench-installed
	$(PY) -m benchmarks.run

report: $(VENV)/.installed
	$(PY) -m benchmarks.report

clean:
	rm -rf $(VENV) build benchmarks/build .pytest_cache
	find . -name __pycache__ -prune -exec rm -rf {} +
