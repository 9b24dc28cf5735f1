# Newcomer entry points: `make demo` and `make test` create .venv when missing,
# install the package with its extras, then run.
PYTHON ?= python3
VENV ?= .venv
OUT ?= results
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test lint bench clean

$(STAMP): setup.py setup.cfg package.xml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test,ros]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/grasp-demo --mode both --out $(OUT)

# Two tests at a time (a test file stays in one worker, on a DDS domain of its own), then the
# tests that assert on wall-clock time alone (test/conftest.py: REAL_TIME_TESTS).
test: $(STAMP)
	$(BIN)/python -m pytest -q -n 2 --dist loadfile -m 'not realtime' test
	$(BIN)/python -m pytest -q -m realtime test

bench: $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[test,ros,bench]'
	$(BIN)/grasp-bench

lint: $(STAMP)
	$(BIN)/ruff check .

clean:
	rm -rf $(VENV) $(OUT) build *.egg-info
