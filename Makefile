# The README's two set-up commands: `make demo` and `make test`. Both create .venv if missing and install.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: demo test paper clean

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[test]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/casadi-ws demo

test: $(STAMP)
	$(BIN)/python -m pytest -q

paper: $(STAMP)
	$(BIN)/python scripts/reproduce_paper.py

clean:
	rm -rf $(VENV) results .pytest_cache
