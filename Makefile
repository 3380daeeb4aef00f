# The two commands (README): `make run` (the main job) and `make test` (the test suite); also `make bench`
# (the benchmarks, benchmarks/README.md) and `make docs` (the documentation site into site/).  Each creates a
# local virtual environment in .venv on first use.
PYTHON ?= python3
VENV   := .venv
STAMP  := $(VENV)/.installed-stamp
# setuptools warns on every editable install whose package folder is named otherwise (tuning/ is jaxobs_tuning)
# that a folder named like the package could shadow it; none is (tests/test_cli.py checks the package list)
PIP    := PYTHONWARNINGS="ignore:Editable installation" $(VENV)/bin/python -m pip

.PHONY: run test test-slow test-repro lint typecheck bench docs docs-serve clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PIP) install --quiet --upgrade pip
	$(PIP) install --quiet -e ".[test,bench]"
	touch $(STAMP)

run: $(STAMP)
	$(VENV)/bin/jaxobs tune --out out/tune --force

# pytest exits 5 when it collects nothing: for the main suite that is a broken
# checkout and fails; for the slow suite it only means there are no slow tests.
# -n auto: one pytest worker per core (pytest-xdist); XLA compiles on one thread, so two workers on two cores
# halve the wall time.  Compilations are cached across runs (tests/conftest.py).
test: $(STAMP)
	@$(VENV)/bin/python -m pytest -m "not slow and not repro" -n auto; rc=$$?; \
	if [ $$rc -eq 5 ]; then echo "make test: pytest collected no tests"; exit 1; fi; exit $$rc

test-slow: $(STAMP)
	@$(VENV)/bin/python -m pytest -m slow -n auto; rc=$$?; \
	if [ $$rc -eq 5 ]; then echo "make test-slow: no slow tests"; exit 0; fi; exit $$rc

# checks of many minutes, a paper's whole reproduction through the command line among them: not in CI's budget
test-repro: $(STAMP)
	$(VENV)/bin/python -m pytest -m repro -n auto

# ruff: lint and formatting (line length 120), as CI runs it
lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

# pyright, basic mode, over jaxobs/ and tuning/ ([tool.pyright] in pyproject.toml), as CI runs it
typecheck: $(STAMP)
	$(VENV)/bin/pyright

# The full benchmark run (over 30 min on 2 cores, benchmarks/README.md): the throughput rows with the batch-inner numba
# kernels (~29 min), then time to result (make run cold and warm) and scale (FLL 10^6, drive 10^5 scenarios), ~2 min
# together on a quiet machine; results in benchmarks/results/<date>.json; run from the repository root (benchmarks/
# is not part of the installed package). Quick look: .venv/bin/python -m benchmarks --quick (throughput only)
bench: $(STAMP)
	$(VENV)/bin/python -m benchmarks --out benchmarks/results/$$(date +%Y-%m-%d).json

# The documentation site (mkdocs.yml) into site/, --strict: a broken link, a missing page or a docstring that
# mkdocstrings cannot render fails the build.  The docs extra goes into .venv once (its own stamp).  The TOML
# reference and the API pages are generated while it builds (docs/hooks/).
DOCS_STAMP := $(VENV)/.docs-stamp
$(DOCS_STAMP): $(STAMP)
	$(PIP) install --quiet -e ".[test,bench,docs]"
	touch $(DOCS_STAMP)

# The notebooks are rendered with their stored outputs (python notebooks/execute.py); EXECUTE=1 runs them again
# while building (minutes)
docs: $(DOCS_STAMP)
	NO_MKDOCS_2_WARNING=1 JAXOBS_DOCS_EXECUTE=$(if $(EXECUTE),true,false) $(VENV)/bin/mkdocs build --strict --quiet

# The site served at http://127.0.0.1:8000, rebuilt when a page or docstring changes (site/index.html opened as a
# file works as well: use_directory_urls is off, search is offline)
docs-serve: $(DOCS_STAMP)
	NO_MKDOCS_2_WARNING=1 JAXOBS_DOCS_EXECUTE=false $(VENV)/bin/mkdocs serve --dev-addr 127.0.0.1:8000

clean:
	rm -rf $(VENV) out site .pytest_cache
