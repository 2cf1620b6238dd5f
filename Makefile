# Two commands on a fresh clone: `make generate` and `make test`.
PYTHON_SYS ?= python3
VENV := .venv
PY := $(VENV)/bin/python
ROBOTS := lwr4 lwr4_hartl panda

.PHONY: generate test bench report clean

$(VENV)/.installed: pyproject.toml
	$(PYTHON_SYS) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test,bench]'
	touch $@

generate: $(VENV)/.installed
	$(PY) -m generator generate $(addprefix robots/,$(addsuffix .yaml,$(ROBOTS))) --out generated

test: $(VENV)/.installed
	$(PY) -m pytest

bench: $(VENV)/.installed
	$(PY) -m benchmarks.run

report: $(VENV)/.installed
	$(PY) -m benchmarks.report

clean:
	rm -rf $(VENV) build benchmarks/build .pytest_cache
	find . -name __pycache__ -prune -exec rm -rf {} +
