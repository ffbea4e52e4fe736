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

# the benchmarks' baselines, not twinkit's dependencies: pymeshlab (the thesis's mesh route that
# bench_pointcloud.py races) and xatlas (the UV unwrapper compared with the built-in charts)
BENCH_STAMP := .venv/.twinkit-bench-setup
$(BENCH_STAMP): $(STAMP)
	$(PY) -m pip install --quiet --disable-pip-version-check "pymeshlab>=2023.12" "xatlas>=0.0.9"
	@touch $@

bench: $(BENCH_STAMP)
	$(PY) bench/run_all.py

clean:
	rm -rf outputs .pytest_cache
