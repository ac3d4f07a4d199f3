# Two commands do everything on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
PIP    := $(PY) -m pip
STAMP_RUN  := $(VENV)/.installed-run
STAMP_TEST := $(VENV)/.installed-test

.PHONY: demo test venv system-deps experiments bench bench-check firmware clean

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

# Test files run in parallel, one worker per core; each file stays on one worker (its module fixtures run once).
test: $(STAMP_TEST) system-deps
	$(PY) -m pytest -q -n auto --dist loadfile

experiments: $(STAMP_RUN)
	$(PY) -m experiments.run_all

# Every benchmark with its default arguments (hours on 2 cores: the rescue table and the hearing table are the
# longest); each writes benchmarks/results/<name>.json, then docs/results.md is rendered from them.
# A benchmark that fails (e.g. bench_firmware without the AVR toolchain) does not stop the others; make bench
# then names it and exits non-zero.
bench: $(STAMP_TEST) system-deps
	@failed=""; for b in benchmarks/bench_*.py; do echo "== $$b"; $(PY) $$b || failed="$$failed $$b"; done; \
	$(PY) tools/write_results.py; \
	if [ -n "$$failed" ]; then echo "make bench: failed:$$failed"; exit 1; fi

# Before a release: every speed benchmark again with the arguments its stored figures were measured with,
# compared with them (exit non-zero when one is more than 1.5x worse, or none is stored). Nothing is written.
SPEED_BENCH := acoustics env health hearing listen locate_memory physics scenario srp tracking
bench-check: $(STAMP_TEST)
	@failed=""; for b in $(SPEED_BENCH); do \
	args=$$($(PY) benchmarks/_results.py argv $$b) || { failed="$$failed $$b"; continue; }; \
	echo "== bench_$$b $$(echo $$args) --check"; \
	$(PY) benchmarks/bench_$$b.py $$args --check || failed="$$failed $$b"; done; \
	if [ -n "$$failed" ]; then echo "make bench-check: not within 1.5x of the stored figures:$$failed"; exit 1; fi

clean:
	rm -rf $(VENV) build dist src/*.egg-info .pytest_cache
