# Two commands on a fresh machine: `make demo` and `make test` (docs/guides/contracts.md).
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test bench lint docs screenshots clean

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[dev]"
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/jaxvs demo --out demo-report

test: $(STAMP)
	$(PY) -m pytest -n 2 --dist loadgroup --max-worker-restart=0 --durations=15 tests
	$(PY) -m pytest --nbmake --nbmake-timeout=900 notebooks -p no:randomly -o filterwarnings=
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict --quiet

bench: $(STAMP)
	for b in benchmarks/*.py; do $(PY) $$b || exit 1; done

docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict

# Screenshots of the three report.html files in headless Chromium, for the docs
# (docs/img/report_*.png). Installs Chromium from the system packages when missing.
screenshots: $(STAMP)
	@command -v chromium >/dev/null || command -v chromium-browser >/dev/null || \
	command -v google-chrome >/dev/null || { \
	  echo "make screenshots: Chromium is missing; installing the system package 'chromium'"; \
	  if [ "$$(id -u)" = 0 ]; then SUDO=; elif command -v sudo >/dev/null; then SUDO=sudo; \
	  else echo "make screenshots: cannot install Chromium (not root, no sudo); install the \
	package 'chromium' and run again"; exit 1; fi; \
	  $$SUDO apt-get update -qq && \
	  DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y --no-install-recommends chromium \
	  || { echo "make screenshots: apt-get could not install chromium (see above)"; exit 1; }; }
	$(PY) docs/screenshot_reports.py

lint: $(STAMP)
	$(VENV)/bin/ruff check jaxvs tests benchmarks

clean:
	rm -rf $(VENV) demo-report .pytest_cache site
