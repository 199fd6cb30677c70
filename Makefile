# semreplay: `make demo` and `make test` set everything up on a fresh machine.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
DEMO_DIR ?= demo_out
DEMO_SEED ?= 7
DEMO_FRAMES ?= 300

.PHONY: demo test lint bench sysdeps clean

# System libraries that open3d and pyrealsense2 load (libusb, OpenMP, GL); installed only if missing.
sysdeps:
	@bash scripts/sysdeps.sh

$(STAMP): pyproject.toml | sysdeps
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q torch==2.13.0
	$(BIN)/python -m pip install -q -e '.[all,dev]'
	@touch $(STAMP)

lint: $(STAMP)
	$(BIN)/ruff format --check .
	$(BIN)/ruff check .
	$(BIN)/mypy

test: $(STAMP) lint
	$(BIN)/pytest

DEMO_REC := $(DEMO_DIR)/sim_seed$(DEMO_SEED).mcap

demo: $(STAMP)
	$(BIN)/semreplay-capture simulate $(DEMO_REC) --seed $(DEMO_SEED) --frames $(DEMO_FRAMES)
	$(BIN)/semreplay-capture info $(DEMO_REC)
	$(BIN)/semreplay-process run $(DEMO_REC) --out $(DEMO_DIR)/run --config samples/sample.toml --force
	@echo
	@echo "outputs: $(DEMO_DIR)/run (recording.rrd, map_fused.ply, map_refined.ply, trajectory.tum, metrics.json, config.toml)"
	@echo "open the timeline with: $(BIN)/semreplay-view $(DEMO_DIR)/run/recording.rrd   (or add --web)"

bench: $(STAMP)
	$(BIN)/python -m benchmarks

clean:
	rm -rf $(VENV) $(DEMO_DIR) .mypy_cache .pytest_cache .ruff_cache
