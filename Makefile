# iceskate: every target sets itself up first (scripts/bootstrap.sh is idempotent and takes a
# second or two when nothing changed), so `make test` works on a fresh clone.
SHELL := /bin/bash
.DEFAULT_GOAL := help

ROOT := $(abspath $(dir $(lastword $(MAKEFILE_LIST))))
# Run a command inside the project environment (venv + ros_ws/install + DDS on loopback).
IN_ENV := cd $(ROOT) && . ./env.sh &&

# Extra pytest arguments, e.g. `make test PYTEST_ARGS='-k bag -x'`.
PYTEST_ARGS ?=
# Test processes (pytest-xdist; each test isolates its DDS domain, logs and folders): the suite
# is mostly one core's work at a time, so two share a 2-core machine well. 0: one process.
PYTEST_WORKERS ?= 2

.PHONY: help setup test run study lint fix lock clean distclean bench stress sanitize

help:
	@echo 'make setup      create .venv from requirements.lock and colcon-build ros_ws (idempotent)'
	@echo 'make test       setup, then the whole pytest suite (what CI runs)'
	@echo 'make run        setup, then run a scene headless (SCENE=skate, OUT=runs/<scene>-<time>)'
	@echo 'make study      setup, then the shipped arm_swing study into runs/arm_swing (~20 s)'
	@echo 'make bench      setup, then work-precision and laziness benchmarks into runs/bench (~4-8 min)'
	@echo 'make stress     setup, then the stress cases and stand for STRESS_DURATION=600 s (long)'
	@echo 'make sanitize   setup, then the native core under ASan+UBSan: its tests and the skate scene'
	@echo 'make lint       setup, then ruff check of ros_ws/src and tests'
	@echo 'make fix        setup, then ruff check --fix (safe fixes only, e.g. import order)'
	@echo 'make lock       re-resolve requirements.in into requirements.lock (uv, Python 3.11)'
	@echo 'make clean      remove ros_ws/build, install and log (and their -sanitize twins)'
	@echo 'make distclean  clean, and remove .venv'

setup:
	@bash $(ROOT)/scripts/bootstrap.sh

test: setup
	$(IN_ENV) python -m pytest tests -ra --durations=10 -n $(PYTEST_WORKERS) --dist worksteal $(PYTEST_ARGS)

# The main job: one scene, headless (same control code and rate as the ROS nodes).
SCENE ?= skate
OUT ?= runs/$(SCENE)-$(shell date +%Y%m%d-%H%M%S)
run: setup
	$(IN_ENV) run_scene $(SCENE) --out $(OUT) --arm-swing-ratio $(RUN_ARGS)

# The shipped parameter study (iceskate_study/studies/arm_swing.yaml): table and heat maps into
# runs/arm_swing (a second call resumes; STUDY=... for another study or a SPEC path).
STUDY ?= arm_swing
study: setup
	$(IN_ENV) sweep $(STUDY) --out runs/$(notdir $(basename $(STUDY)))

# The native core (iceskate_native) built under AddressSanitizer + UndefinedBehaviorSanitizer in
# ros_ws/build-sanitize and install-sanitize; runs tests/iceskate_native (not slow) and the whole skate scene
# with it, and fails on any sanitizer report (docs/usage.md, "Tests").
sanitize: setup
	bash $(ROOT)/scripts/sanitize.sh

lint: setup
	$(IN_ENV) ruff check ros_ws/src tests

fix: setup
	$(IN_ENV) ruff check --fix ros_ws/src tests

# Needs uv: the venv's (after `make setup`) or a uv on PATH (pinned in scripts/bootstrap.sh).
lock:
	cd $(ROOT) && $$( [ -x .venv/bin/uv ] && echo .venv/bin/uv || echo uv ) pip compile \
	  --python-version 3.11 --python-platform x86_64-manylinux_2_28 \
	  requirements.in -o requirements.lock

clean:
	rm -rf $(ROOT)/ros_ws/build $(ROOT)/ros_ws/install $(ROOT)/ros_ws/log
	rm -rf $(ROOT)/ros_ws/build-sanitize $(ROOT)/ros_ws/install-sanitize $(ROOT)/ros_ws/log-sanitize

distclean: clean
	rm -rf $(ROOT)/.venv

# Benchmarks (docs/performance.md): outputs in runs/bench; BENCH_ARGS=--quick for a ~1-2 min version.
BENCH_ARGS ?=
bench: setup
	$(IN_ENV) python benchmarks/bench_work_precision.py --out runs/bench $(BENCH_ARGS) && python benchmarks/bench_laziness.py $(BENCH_ARGS)

# Numerical-stability stress cases plus a long stand run (simulated seconds below).
STRESS_DURATION ?= 600
stress: setup
	$(IN_ENV) python benchmarks/stress.py --long --long-duration $(STRESS_DURATION) --json runs/bench/stress.json
