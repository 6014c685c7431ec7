# stiffmap: `make demo` and `make test` work from a clean clone.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test test-fast test-long lint bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --disable-pip-version-check -e '.[dev,dask]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/stiffmap demo

test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/lint-imports --no-cache
	$(BIN)/python -m pytest -n 2 --dist loadscope -q -m "not long"

# The fast loop: no test marked slow or long (CONTRIBUTING.md).
test-fast: $(STAMP)
	$(BIN)/python -m pytest -n 2 --dist loadscope -q -m "not slow and not long"

# The long profile: demo-size end-to-end checks, run by CI after `make test`.
test-long: $(STAMP)
	$(BIN)/python -m pytest -n 2 --dist loadscope -q -m long

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

bench: $(STAMP)
	for b in benchmarks/bench_*.py; do $(BIN)/python $$b || exit 1; done

clean:
	rm -rf $(VENV) build src/*.egg-info .pytest_cache .ruff_cache
