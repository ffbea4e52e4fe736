# twinkit: two commands on a fresh machine.
#   make demo    set up, then run the main job on the built-in demo site
#   make test    set up, then run every test (the sessions side by side, one per core;
#                TWINKIT_TEST_JOBS=1 make test, or PYTEST_ARGS="--jobs 1", runs them one at a time)
#   make bench   set up, then run the benchmarks (prints tables, writes bench/results/)
PY      := .venv/bin/python
STAMP   := .venv/.twinkit-setup
SITE    ?= demo
RECIPE  ?= pointcloud_site
ARGS    ?=
PYTEST_ARGS ?=

.PHONY: setup demo test bench clean

$(STAMP): scripts/setup.sh pyproject.toml $(wildcard plugins/*/pyproject.toml) package.json package-lock.json
	bash scripts/setup.sh
	@touch $@

setup: $(STAMP)

demo: $(STAMP)
	.venv/bin/twinkit recipe=$(RECIPE) site=$(SITE) $(ARGS)

test: $(STAMP)
	$(PY) scripts/run_tests.py $(PYTEST_ARGS)

bench: $(STAMP)
	$(PY) bench/run_all.py

clean:
	rm -rf outputs .pytest_cache
