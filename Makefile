# Two commands do everything on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
PIP    := $(PY) -m pip
STAMP_RUN  := $(VENV)/.installed-run
STAMP_TEST := $(VENV)/.installed-test

.PHONY: demo test venv system-deps experiments bench firmware clean

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PIP) install --quiet --upgrade pip

$(STAMP_RUN): pyproject.toml | $(PY)
	$(PIP) install --quiet -e .
	touch $@

$(STAMP_TEST): pyproject.toml | $(PY)
	$(PIP) install --quiet -e ".[test]"
	touch $@ $(STAMP_RUN)

venv: $(STAMP_RUN)

# Debian packages the tests need beyond PyPI (AVR toolchain, simavr, OSMesa).
# Installed only when missing and when apt-get is usable; tests that need them
# skip with a clear reason otherwise.
system-deps:
	@bash scripts/system-deps.sh

demo: $(STAMP_RUN)
	$(PY) -m ssl_sim.demo

test: $(STAMP_TEST) system-deps
	$(PY) -m pytest -q

experiments: $(STAMP_RUN)
	$(PY) -m experiments.run_all

# Every benchmark with its default arguments (hours on 2 cores: the rescue table and the hearing table are the
# longest); each writes benchmarks/results/<name>.json, then docs/results.md is rendered from them.
bench: $(STAMP_TEST) system-deps
	for b in benchmarks/bench_*.py; do echo "== $$b"; $(PY) $$b || exit 1; done
	$(PY) tools/write_results.py

clean:
	rm -rf $(VENV) build dist src/*.egg-info .pytest_cache
