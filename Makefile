# The README's two set-up commands: `make demo` and `make test`. Both create .venv if missing; `make demo`
# installs the package alone, `make test` adds the test tools and the `fast` extra (README: their sizes).
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
BASE   := $(VENV)/.installed-base

.PHONY: demo test paper clean

# the package alone: what the demo needs (SuperLU; no test tools, no MKL)
$(BASE): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e .
	touch $(BASE)

# with the test tools and the `fast` extra (PARDISO, which the tests cover beside SuperLU)
$(STAMP): pyproject.toml $(BASE)
	$(BIN)/python -m pip install -q -e '.[test,fast]'
	touch $(STAMP)

demo: $(BASE)
	$(BIN)/casadi-ws demo

# the report's browser test needs a chromium: Debian's package, installed once if missing (as root)
test: $(STAMP)
	@command -v chromium >/dev/null 2>&1 || command -v chromium-browser >/dev/null 2>&1 || \
	  { [ "$$(id -u)" = 0 ] && apt-get install -y -q chromium >/dev/null 2>&1; } || \
	  echo "make test: no chromium and it could not be installed: the report's browser test will skip (with this reason)"
	$(BIN)/python -m pytest -q -rs -n 2 --dist loadgroup --durations 25

paper: $(STAMP)
	$(BIN)/python scripts/reproduce_paper.py

clean:
	rm -rf $(VENV) results .pytest_cache
