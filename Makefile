# Two commands do all the set-up on a fresh machine: `make validate` (the main job) and `make test`.
PY ?= python3
STAMP := .make-installed

.PHONY: install test validate validate-full bench reference clean

$(STAMP): pyproject.toml
	$(PY) -m pip install -q -e ".[dev,kratos]"
	@touch $(STAMP)

install: $(STAMP)

test: $(STAMP)
	$(PY) -m pytest -q

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
