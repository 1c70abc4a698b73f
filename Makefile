# horizon_mpc: developer entry points. Needs only python3 (>= 3.11) and make.
#
#   make demo   set up .venv from PyPI, then run the closed-loop demo (outputs in out/)
#   make test   set up .venv the same way, then ruff check + the full pytest suite (incl. slow)
#
# Setup is idempotent: pip runs again only when setup.py, setup.cfg or pyproject.toml change
# (the stamp file name carries a hash of them); the data files (ament index marker,
# package.xml, configs, launch files, launchers) are re-copied only when one of them changes.

SHELL := /bin/bash
.DEFAULT_GOAL := help

PYTHON ?= python3
VENV ?= .venv
PEER_VENV ?= .venv-peer
VENV_ABS := $(abspath $(VENV))
VPY := $(VENV_ABS)/bin/python

# Hash of the files that decide what pip installs (computed before PATH points at the venv).
DEPS_HASH := $(shell $(PYTHON) -c 'import hashlib, sys; h = hashlib.sha256(); \
	[h.update(open(f, "rb").read()) for f in sys.argv[1:]]; print(h.hexdigest()[:16])' \
	setup.py setup.cfg pyproject.toml)
DEPS_STAMP := $(VENV)/.horizon_mpc-deps-$(DEPS_HASH)
DATA_STAMP := $(VENV)/.horizon_mpc-data.stamp
DATA_FILES := package.xml resource/horizon_mpc $(wildcard scripts/*) $(wildcard config/*.yaml) \
	$(wildcard config/motions/*.yaml config/commands/*.yaml) \
	$(wildcard launch/*.py launch/*.xml launch/*.yaml) $(wildcard doc/*.md)

# Comparison peer for the benchmarks: Crocoddyl crashes with pin 4.1, so it gets its own venv
# with pin 4.0 (see doc/benchmarks.md).
PEER_REQUIREMENTS := crocoddyl==3.2.1 pin==4.0.0 libpinocchio==4.0.0 example-robot-data numpy pyyaml
PEER_HASH := $(shell $(PYTHON) -c 'import hashlib, sys; \
	print(hashlib.sha256(" ".join(sys.argv[1:]).encode()).hexdigest()[:16])' $(PEER_REQUIREMENTS))
PEER_STAMP := $(PEER_VENV)/.horizon_mpc-peer-$(PEER_HASH)
BENCH ?= $(sort $(wildcard bench/bench_*.py))

# Network hygiene: DDS traffic stays on 127.0.0.1, in a ROS domain private to this make run
# (valid ids: 1-101, 215-232, never the environment's own ROS_DOMAIN_ID, the domain of the
# user's other nodes; override with `make demo ROS_DOMAIN_ID=7`).
ROS_DOMAIN_ID := $(shell $(PYTHON) -c 'import os; ids = [*range(1, 102), *range(215, 233)]; \
	ids = [i for i in ids if str(i) != os.environ.get("ROS_DOMAIN_ID", "").strip()]; \
	print(ids[os.getppid() % len(ids)])')
export ROS_DOMAIN_ID
export ROS_AUTOMATIC_DISCOVERY_RANGE := LOCALHOST
# `ros2 run`-style lookups (ament_index_python) need the venv prefix on AMENT_PREFIX_PATH.
export VIRTUAL_ENV := $(VENV_ABS)
export PATH := $(VENV_ABS)/bin:$(PATH)
export AMENT_PREFIX_PATH := $(VENV_ABS)$(if $(AMENT_PREFIX_PATH),:$(AMENT_PREFIX_PATH))
export MPLBACKEND ?= Agg
export PIP_DISABLE_PIP_VERSION_CHECK := 1
# the benchmark peer: a HORIZON_MPC_PEER_PYTHON of the caller is used as given (no
# $(PEER_VENV) is built), else $(PEER_VENV)'s, created on demand by `make bench`
ifdef HORIZON_MPC_PEER_PYTHON
BENCH_PEER :=
else
export HORIZON_MPC_PEER_PYTHON := $(abspath $(PEER_VENV))/bin/python
BENCH_PEER := peer-venv
endif

.PHONY: help setup demo test lint bench peer-venv clean FORCE

help:
	@echo "horizon_mpc make targets:"
	@echo "  make demo       set up $(VENV), run the closed-loop walk demo (writes out/closed_loop)"
	@echo "  make test       set up $(VENV), ruff check + full pytest suite (incl. slow tests)"
	@echo "  make setup      create/update $(VENV) only (idempotent, fast when nothing changed)"
	@echo "  make lint       ruff check"
	@echo "  make bench      run bench/bench_*.py (peer: HORIZON_MPC_PEER_PYTHON if set, else $(PEER_VENV), created on demand)"
	@echo "  make peer-venv  create $(PEER_VENV) with Crocoddyl + pin 4.0 (benchmark peer)"
	@echo "  make clean      remove build artefacts (build/, *.egg-info); keeps the venvs"

setup: $(DATA_STAMP)

$(VPY):
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else \
		"horizon_mpc needs Python >= 3.11; $(PYTHON) is " + sys.version.split()[0])'
	@echo "==> Creating the virtual environment $(VENV) with $$($(PYTHON) --version)"
	$(PYTHON) -m venv $(VENV)

# The stamp cannot see an out-of-band `pip uninstall`: reinstall when the venv has no
# horizon_mpc distribution at all.
ifeq ($(wildcard $(VENV)/lib/python3*/site-packages/horizon_mpc-*.dist-info),)
$(DEPS_STAMP): FORCE
endif

$(DEPS_STAMP): | $(VPY)
	@echo "==> Installing horizon_mpc (editable) and its dependencies from PyPI into $(VENV):"
	@echo "    casadi, pinocchio, example-robot-data, pybullet, ROS 2 Jazzy rclpy + messages,"
	@echo "    numpy/scipy/matplotlib, pytest/hypothesis/ruff (about 1-2 min the first time)"
	$(VPY) -m pip install --progress-bar off -e ".[test]"
	@rm -f $(VENV)/.horizon_mpc-deps-*
	@touch $@
	@echo "==> Dependencies installed (stamp $(notdir $@))"

# pip's editable install never installs data_files: copy them into the venv prefix so that
# `<venv>/share/ament_index/.../horizon_mpc` and `<venv>/lib/horizon_mpc/<exe>` exist.
$(DATA_STAMP): $(DEPS_STAMP) setup.py $(DATA_FILES)
	@echo "==> Installing the ament index marker, package.xml, configs and launchers into $(VENV)"
	$(VPY) -W "ignore:setup.py install is deprecated" setup.py --quiet \
		install_data --install-dir $(VENV_ABS) --force
	@touch $@

demo: setup
	@echo "==> Closed-loop demo (ROS_DOMAIN_ID=$(ROS_DOMAIN_ID), localhost only) -> out/closed_loop"
	$(VPY) -m horizon_mpc.closed_loop --out out/closed_loop --domain-id $(ROS_DOMAIN_ID)

lint: setup
	@echo "==> ruff check"
	$(VENV_ABS)/bin/ruff check .

# Lint and tests both run (so one report shows everything); the target fails if either fails.
test: setup
	@echo "==> ruff check"; \
	$(VENV_ABS)/bin/ruff check . ; lint=$$?; \
	echo "==> pytest, full suite incl. slow tests (ROS_DOMAIN_ID private per session, localhost)"; \
	$(VPY) -m pytest $(PYTEST_ARGS); tests=$$?; \
	if [ $$lint -ne 0 ]; then echo "==> ruff check FAILED"; fi; \
	if [ $$tests -ne 0 ]; then exit $$tests; fi; \
	exit $$lint

peer-venv: $(PEER_STAMP)

$(PEER_STAMP):
	@echo "==> Creating $(PEER_VENV): $(PEER_REQUIREMENTS) (benchmark comparison peer)"
	@test -x $(PEER_VENV)/bin/python || $(PYTHON) -m venv $(PEER_VENV)
	$(PEER_VENV)/bin/python -m pip install --progress-bar off $(PEER_REQUIREMENTS)
	@rm -f $(PEER_VENV)/.horizon_mpc-peer-*
	@touch $@

bench: setup $(BENCH_PEER)
	@if [ -z "$(BENCH)" ]; then echo "no benchmarks in bench/ yet"; exit 0; fi; \
	for script in $(BENCH); do \
		echo "==> $$script"; \
		$(VPY) $$script || exit $$?; \
	done

clean:
	rm -rf build horizon_mpc.egg-info

FORCE:

# `make print-DEPS_STAMP` shows a variable (used by test/test_package.py).
print-%:
	@echo '$($*)'
