# Wall Inspector: two commands on a fresh machine.
#   make demo   installs everything into .venv and flies a short rollout (prints a summary, writes a picture)
#   make test   installs everything into .venv, lints (ruff), type-checks (mypy), builds the docs and runs the test suite
#   make docs   builds the documentation site into build/site (warnings are errors)
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
OUT    ?= out
SITE   ?= build/site
# MkDocs 1.6 prints a banner about its successor on every build; it is not a warning of this site's
export NO_MKDOCS_2_WARNING := 1

.PHONY: install demo test docs clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# torch is pinned first: 2.13.0 is the CPU build available on this machine's disk;
# an unpinned torch would pull a multi-GB CUDA build.
$(VENV)/.installed: pyproject.toml $(BIN)/python
	$(BIN)/python -m pip install --quiet torch==2.13.0
	$(BIN)/python -m pip install --quiet -e ".[notebooks,test,ray,export,docs]"
	touch $@

install: $(VENV)/.installed

demo: install
	$(BIN)/wall-inspector demo --out $(OUT)

# the documentation site (mkdocs.yml): every warning is an error; the notebooks are shown as committed, never run
docs: install
	$(BIN)/mkdocs build --strict --site-dir $(SITE)

# lint, type check, the test suite (settings in pyproject.toml), then the documentation site with warnings as errors
test: install
	$(BIN)/ruff check .
	$(BIN)/mypy
	$(BIN)/python -m pytest -q
	$(BIN)/mkdocs build --strict --quiet --site-dir $(SITE)

clean:
	rm -rf $(VENV) $(OUT) build $(SITE) *.egg-info
