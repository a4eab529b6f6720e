# Every target creates the virtualenv on first use, so a fresh checkout needs only `make run`
# or `make test`.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
# Modules compiled with mypyc (see setup.py): an edit to one of them rebuilds its extension.
MYPYC_LISTS := $(wildcard */mypyc.list */*/mypyc.list)
MYPYC_SOURCES := $(foreach f,$(MYPYC_LISTS),$(addprefix $(dir $(f)),$(shell sed 's/\#.*//' $(f))))

.PHONY: run test bench lint clean corpus corpus-baseline mutation coverage soak

# The first build takes minutes (measured 5-16 on a busy 2-core box): say so, and what runs.
$(STAMP): pyproject.toml setup.py $(MYPYC_LISTS) $(MYPYC_SOURCES)
	@echo "==> fmscell: installing into $(VENV): about 5-15 minutes the first time (dependencies,"
	@echo "    then mypyc compiles $(words $(MYPYC_SOURCES)) hot modules to C); later runs skip this."
	@echo "    FMSCELL_PURE_PYTHON=1 make ... skips the compile (same behaviour, slower runs)."
	@date +%s > $(VENV).build-start 2>/dev/null || true
	@echo "==> [1/2] virtualenv $(VENV)"
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	@echo "==> [2/2] dependencies, then 'Building editable for fmscell': the mypyc compile of"
	@echo "    $(words $(MYPYC_SOURCES)) modules, the long part (minutes with little output)"
	$(PY) -m pip install --progress-bar off -e '.[dev,bench]'
	touch $(STAMP)
	@echo "==> installed in $$(( $$(date +%s) - $$(cat $(VENV).build-start 2>/dev/null || date +%s) )) s"
	@rm -f $(VENV).build-start

# RUN_ARGS: options of `fmscell run` (docs/cell.md); fault injection is on for the tour.
RUN_ARGS ?= --faults

run: $(STAMP)
	$(VENV)/bin/fmscell run $(RUN_ARGS)

test: $(STAMP)
	$(PY) -m pytest -n 2 -q

# The corpus of real part programs (../shared/reference/corpus/gcode, never copied here):
# a per-file table and `N passed, M failed` against tests/cnc/corpus_expected.yaml.
corpus: $(STAMP)
	$(PY) -m tests.cnc.corpus_report

# Regenerate that baseline from today's results (expected-invalid entries are kept).
corpus-baseline: $(STAMP)
	$(PY) -m tests.cnc.corpus_report --write

# Mutation testing of the pure cores with mutmut (tests/mutation.py: targets and their bounded
# test selections): minutes per module, so kept out of `make test`. One module:
# `make mutation MUTATION_ARGS=dnc/rules.py`; `python -m tests.mutation --list` names them.
MUTATION_ARGS ?=
mutation: $(STAMP)
	nice $(PY) -m tests.mutation --min-score 90 $(MUTATION_ARGS)

# Line + branch coverage of the suite, subprocesses included (pyproject [tool.coverage.run]);
# server/ first, then everything. mypyc-compiled modules cannot be traced and are left out of
# the report (FMSCELL_PURE_PYTHON=1 installs measure them too). One folder:
# `make coverage COVERAGE_ARGS=tests/server`. COVERAGE_FILE is absolute so that subprocesses
# running in a test's tmp_path write their data here too.
COVERAGE_ARGS ?=
comma := ,
empty :=
space := $(empty) $(empty)
COVERAGE_OMIT := $(subst $(space),$(comma),$(strip $(MYPYC_SOURCES) */migrations/*))
coverage: $(STAMP)
	rm -rf build/coverage && mkdir -p build/coverage
	-COVERAGE_FILE=$(CURDIR)/build/coverage/.coverage \
		$(PY) -m coverage run -m pytest -n 2 -q -p no:cacheprovider $(COVERAGE_ARGS)
	$(PY) -m coverage combine -q
	@echo "==> server/"
	$(PY) -m coverage report --include='server/*' --omit='$(COVERAGE_OMIT)'
	@echo "==> all packages"
	$(PY) -m coverage report --omit='$(COVERAGE_OMIT)' --format=total \
		| sed 's/^/total: /;s/$$/ %/'
	$(PY) -m coverage html -q -d build/coverage/html --omit='$(COVERAGE_OMIT)'

# The long kill -9 campaign (docs/recovery.md): 20 host and 20 machine-process kills at seeded
# random moments of a running cell, on SQLite then PostgreSQL; one JSON object, exit 1 if a
# part was lost, made twice or stuck. Tens of minutes: kept out of `make test` and `make bench`
# runs its short version. `make soak-kill KILL_ARGS="--kills 5 --seed 7"`.
.PHONY: soak-kill
KILL_ARGS ?= --kills 20
soak-kill: $(STAMP)
	$(PY) bench/bench_kill_campaign.py $(KILL_ARGS)

bench: $(STAMP)
	$(PY) bench/run_all.py

# Soaks, kept out of `make test` and `make bench`: bench/bench_soak.py (the default cell for
# an hour: jobs looping, SSE clients churning, a fault a minute cleared and recovered; parts
# counted = made, nothing stuck, host RSS growth in MB/h), then every bench/bench_soak_*.py.
# Each prints ONE JSON object and exits 1 when a check fails; each takes `--short`, its CI
# version (.ci/run: `make soak SOAK_ARGS=--short`, bench_soak.py then runs 2 minutes).
SOAK_ARGS ?=
soak: $(STAMP)
	$(PY) bench/bench_soak.py $(SOAK_ARGS)
	for b in bench/bench_soak_*.py; do [ ! -e "$$b" ] || $(PY) "$$b" $(SOAK_ARGS) || exit 1; done

lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache
	find . -name '*.so' -not -path './$(VENV)/*' -delete
