# Every target bootstraps .venv on first use (and again when pyproject.toml changes).
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: run test lint bench bench-speed bench-protocol bench-real clean

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[dev]'
	touch $(STAMP)

run: $(STAMP)
	$(BIN)/squashcal run

test: $(STAMP)
	$(BIN)/python -m pytest -q

lint: $(STAMP)
	$(BIN)/ruff check app worker tests bench
	$(BIN)/ruff format --check app worker tests bench
	$(BIN)/mypy app worker

bench: bench-speed bench-protocol

bench-speed: $(STAMP)
	$(BIN)/python -m bench.speed

bench-protocol: $(STAMP)
	$(BIN)/python -m bench.protocol

# Needs the annotated real images, which are not part of this repository:
#   make bench-real DATA=../shared/data/dev
bench-real: $(STAMP)
	$(BIN)/python -m bench.real $(DATA)

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache
