# Two commands do all the set-up on a fresh machine: `make validate` (the main job) and `make test`.
PY ?= python3
STAMP := .make-installed

.PHONY: install test validate validate-full bench reference clean

$(STAMP): pyproject.toml
	$(PY) -m pip install -q -e ".[dev,kratos]"
	@touch $(STAMP)

install: $(STAMP)

# the tests on every core, at most 4 (pytest-xdist, one test file per worker at a time): most of a first run is
# numba compiling kernels, one at a time per process, so two workers compile about twice as fast;
# OMP_WAIT_POLICY=passive: a worker's idle OpenMP threads sleep instead of spinning on the other worker's core
test: $(STAMP)
	OMP_WAIT_POLICY=passive $(PY) -m pytest -q -n auto --maxprocesses 4 --dist loadfile

validate: $(STAMP)
	$(PY) -m coupler.cli validate

validate-full: $(STAMP)
	$(PY) -m coupler.cli validate --full --live

bench: $(STAMP)
	$(PY) -m coupler.cli bench

reference: $(STAMP)
	$(PY) -m coupler.cli reference

clean:
	rm -rf out reports/cases reports/index.html reports/summary.json reports/bench.json $(STAMP)
