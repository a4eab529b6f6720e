# Every target creates the virtualenv on first use, so a fresh checkout needs only `make run`
# or `make test`.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
# Modules compiled with mypyc (see setup.py): an edit to one of them rebuilds its extension.
MYPYC_LISTS := $(wildcard */mypyc.list */*/mypyc.list)
MYPYC_SOURCES := $(foreach f,$(MYPYC_LISTS),$(addprefix $(dir $(f)),$(shell sed 's/\#.*//' $(f))))

.PHONY: run test bench lint clean corpus corpus-baseline

$(STAMP): pyproject.toml setup.py $(MYPYC_LISTS) $(MYPYC_SOURCES)
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev,bench]'
	touch $(STAMP)

run: $(STAMP)
	$(VENV)/bin/fmscell run

test: $(STAMP)
	$(PY) -m pytest -n 2 -q

# The corpus of real part programs (../shared/reference/corpus/gcode, never copied here):
# a per-file table and `N passed, M failed` against tests/cnc/corpus_expected.yaml.
corpus: $(STAMP)
	$(PY) -m tests.cnc.corpus_report

# Regenerate that baseline from today's results (expected-invalid entries are kept).
corpus-baseline: $(STAMP)
	$(PY) -m tests.cnc.corpus_report --write

bench: $(STAMP)
	$(PY) bench/run_all.py

lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache
	find . -name '*.so' -not -path './$(VENV)/*' -delete
