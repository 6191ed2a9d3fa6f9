# Two entry points for a fresh machine: `make demo` and `make test`.
# Each creates .venv with pip and installs what it needs; running again is safe and quick.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
PYTEST_ARGS ?= -n 2

.PHONY: demo test bench lint venv clean

venv: $(STAMP)

$(STAMP): pyproject.toml
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test,all]'
	@touch $(STAMP)

demo: $(STAMP)
	$(BIN)/lipgen demo --out renders

test: $(STAMP)
	$(BIN)/python -m pytest $(PYTEST_ARGS)

bench: $(STAMP)
	$(BIN)/lipgen bench --force --out renders/bench.json

lint: $(STAMP)
	$(BIN)/ruff check lipgen tests blender_addon

clean:
	rm -rf $(VENV) renders/demo renders/bench.json
