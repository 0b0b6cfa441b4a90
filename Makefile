# Wall Inspector: two commands on a fresh machine.
#   make demo   installs everything into .venv and flies a short rollout (prints a summary, writes a picture)
#   make test   installs everything into .venv, lints (ruff), type-checks (mypy) and runs the test suite
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
OUT    ?= out

.PHONY: install demo test clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# torch is pinned first: 2.13.0 is the CPU build available on this machine's disk;
# an unpinned torch would pull a multi-GB CUDA build.
$(VENV)/.installed: pyproject.toml $(BIN)/python
	$(BIN)/python -m pip install --quiet torch==2.13.0
	$(BIN)/python -m pip install --quiet -e ".[notebooks,test,ray,export]"
	touch $@

install: $(VENV)/.installed

demo: install
	$(BIN)/wall-inspector demo --out $(OUT)

# lint, type check, then the test suite (settings in pyproject.toml)
test: install
	$(BIN)/ruff check .
	$(BIN)/mypy
	$(BIN)/python -m pytest -q

clean:
	rm -rf $(VENV) $(OUT) build *.egg-info
