# Every target bootstraps .venv on first use (and again when pyproject.toml changes).
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: run test lint bench bench-speed bench-protocol bench-real docker-check clean

# The browser tests drive Debian's Chromium (no browser download): installed when missing.
CHROMIUM := /usr/bin/chromium
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[dev]'
	# compile the numerical kernels into numba's on-disk cache once (~80 s on 2 cores), at install
	# as issue 8 asks: otherwise the first calibration, the tests' first processes and the
	# service's first warm-up each compile them, several at once on a fresh checkout
	$(BIN)/python -m app.calib.warmup
	touch $(STAMP)

run: $(STAMP)
	$(BIN)/squashcal run

$(CHROMIUM):
	@command -v apt-get >/dev/null || { echo "install Chromium at $(CHROMIUM) (Debian: chromium chromium-driver)"; exit 1; }
	$(SUDO) apt-get update -qq
	$(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium chromium-driver

# two pytest processes: many tests wait on the service processes, the browser and the database
# they start, and the suite in one process had come within minutes of CI's 20 (1007-1116 s in
# the last fresh-clone runs on 2 cores; 714 s in two processes). The test that stops the shared
# PostgreSQL server runs alone afterwards: beside it, the other process's PostgreSQL tests lost
# their connections ("terminating connection due to administrator command").
test: $(STAMP) $(CHROMIUM)
	$(BIN)/python -m pytest -q -n 2 --durations=25 -m "not stops_postgres"
	$(BIN)/python -m pytest -q -m stops_postgres

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

# Build the Docker image (on a base made from Debian packages when the registry is out of reach),
# run api + worker containers, calibrate a rendered clip, ask /project. Minutes; not in .ci/run.
docker-check:
	docker/check.sh

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache
