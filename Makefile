# Two commands on a fresh machine: `make demo` and `make test` (DESIGN.md §3.1).
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test bench lint docs clean

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[dev]"
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/jaxvs demo --out demo-report

test: $(STAMP)
	$(PY) -m pytest -n 2 --dist loadgroup --max-worker-restart=0 --durations=15 tests
	$(PY) -m pytest --nbmake notebooks -p no:randomly -o filterwarnings=
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict --quiet

bench: $(STAMP)
	for b in benchmarks/*.py; do $(PY) $$b || exit 1; done

docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict

lint: $(STAMP)
	$(VENV)/bin/ruff check jaxvs tests benchmarks

clean:
	rm -rf $(VENV) demo-report .pytest_cache site
