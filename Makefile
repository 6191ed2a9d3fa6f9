# Two entry points for a fresh machine: `make demo` and `make test`.
# Each creates .venv with pip and installs what it needs; running again is safe and quick.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
# xdist's default --dist load: --dist loadscope (a module's tests, and so its module fixtures, in one
# worker) measured 2-3 s less CPU of ~235 s and 3 % better to 15 % worse wall in 2 rounds at load 4-8;
# loadfile no better (issue 22, test22k)
PYTEST_ARGS ?= -n 2

.PHONY: demo test test-fast test-slow test-all bench lint venv clean docs docs-clean browser fuzz bad-inputs espeak

# espeak-ng (GPL-3.0, a system tool, not a lipgen dependency) synthesises test speech with exact
# phone timings for the lip-sync accuracy tests; they skip with a message where it is missing.
espeak:
	@command -v espeak-ng >/dev/null 2>&1 || { [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null \
	  && (apt-get update -qq && apt-get install -y -qq espeak-ng >/dev/null) \
	  || echo "espeak-ng not installed (apt-get install espeak-ng): lip-sync accuracy tests will skip"; }

venv: $(STAMP)

$(STAMP): pyproject.toml
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test,all]'
	@touch $(STAMP)

demo: $(STAMP)
	$(BIN)/lipgen demo --out renders

# `test` is the quick tier: it leaves out the slow set (pyproject addopts: -m 'not slow'), whose tests
# each name their cheaper cover (tests/test_tiers.py); `test-fast` also leaves out the rendering and
# Blender tests; `test-slow` is the slow set alone; `test-all` everything. CI runs test, then test-slow.
test: $(STAMP) espeak
	$(BIN)/python -m pytest $(PYTEST_ARGS)

test-fast: $(STAMP)
	$(BIN)/python -m pytest $(PYTEST_ARGS) -m "not slow and not render and not blender"

test-slow: $(STAMP) espeak
	$(BIN)/python -m pytest $(PYTEST_ARGS) -m slow

test-all: $(STAMP) espeak
	$(BIN)/python -m pytest $(PYTEST_ARGS) -m "slow or not slow"

bench: $(STAMP)
	$(BIN)/lipgen bench --force --out renders/bench.json

# Property-based fuzzing, long profile (make test runs a bounded one).
fuzz: $(STAMP)
	HYPOTHESIS_PROFILE=fuzz $(BIN)/python -m pytest tests/test_fuzz.py $(PYTEST_ARGS)

# Regenerate docs/bad_inputs.md from the cases of tests/test_bad_inputs_table.py.
bad-inputs: $(STAMP)
	LIPGEN_UPDATE_DOCS=1 $(BIN)/python -m pytest tests/test_bad_inputs_table.py -n 0

lint: $(STAMP)
	$(BIN)/ruff check lipgen tests blender_addon docs/_hooks
	$(BIN)/lint-imports

# The documentation site (site/index.html). Strict: any warning (a broken link, a docstring
# mkdocstrings cannot read) fails the build. The pictures are made by lipgen on the first build.
docs: $(STAMP) browser
	$(BIN)/mkdocs build --strict

docs-clean:
	rm -rf site docs/figures docs/reference

# Headless Chromium for the docs' screenshot test (Debian's package; needs root, else skipped).
browser:
	@command -v chromium >/dev/null 2>&1 || { [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1 \
	  && (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null) \
	  || echo "chromium not installed: the docs screenshot test will be skipped"; }

clean:
	rm -rf $(VENV) renders/demo renders/bench.json site docs/figures docs/reference
