# prsm_health: reproducible environment, lint, tests and demo.
# `make venv` builds everything from scratch on a fresh clone (see ../shared/ROS_PIP.md).

SHELL := /bin/bash
.SHELLFLAGS := -euo pipefail -c

PYTHON ?= python3.11
VENV := $(CURDIR)/.venv
BUILD := $(CURDIR)/build
PY := $(VENV)/bin/python
MSGS := msg_defs/prsm_health_msgs
# Limit for the whole pytest run, in seconds (per-test limits: pytest-timeout, pyproject.toml).
TEST_RUN_TIMEOUT ?= 840

# DDS hard rules, not overridable: loopback discovery, UDPv4 as Fast DDS's built-in transports
# (rmw_fastrtps still adds shared memory under LOCALHOST: docs/ros.md). ROS logs go to
# the build tree unless ROS_LOG_DIR is set (the environment's or the command line's wins).
# ROS_DOMAIN_ID is chosen per test process by test/conftest.py, and by the demo target below.
export ROS_AUTOMATIC_DISCOVERY_RANGE := LOCALHOST
export FASTDDS_BUILTIN_TRANSPORTS := UDPv4
export ROS_LOG_DIR ?= $(BUILD)/ros_log

# Stamps live inside the venv, so deleting .venv also forgets what was built into it.
REQS_STAMP := $(VENV)/.stamp-requirements
MSGS_STAMP := $(VENV)/.stamp-msgs
EDITABLE_STAMP := $(VENV)/.stamp-editable

.PHONY: venv lint test demo clean bags bags-check

venv: $(MSGS_STAMP) $(EDITABLE_STAMP)

$(PY):
	$(PYTHON) -m venv $(VENV)
	touch $(VENV)/COLCON_IGNORE

# Install the pinned wheels, then point the wheels' exported CMake files at this venv's
# Python and numpy headers (they name the wheel build container's paths).
$(REQS_STAMP): requirements.txt | $(PY)
	$(PY) -m pip install --quiet -r requirements.txt
	pyinc=$$($(PY) -c 'import sysconfig; print(sysconfig.get_paths()["include"])'); \
	npinc=$$($(PY) -c 'import numpy; print(numpy.get_include())'); \
	grep -rlZ --include='*.cmake' /opt/python/cp311-cp311 $(VENV)/share \
	  | xargs -0 -r sed -i \
	    -e "s|/opt/python/cp311-cp311/include/python3.11|$$pyinc|g" \
	    -e "s|/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include|$$npinc|g"
	touch $@

# Build the interface package with plain cmake and install it into the venv prefix.
$(MSGS_STAMP): $(REQS_STAMP) $(MSGS)/CMakeLists.txt $(MSGS)/package.xml \
		$(wildcard $(MSGS)/msg/*.msg) $(wildcard $(MSGS)/srv/*.srv)
	rm -rf $(BUILD)/msgs
	mkdir -p $(BUILD)
	touch $(BUILD)/COLCON_IGNORE
	AMENT_PREFIX_PATH=$(VENV) cmake -S $(MSGS) -B $(BUILD)/msgs -DCMAKE_PREFIX_PATH=$(VENV) \
	  -DCMAKE_INSTALL_PREFIX=$(VENV) -DPython3_EXECUTABLE=$(PY) -DBUILD_TESTING=OFF > /dev/null
	cmake --build $(BUILD)/msgs -j 2 > /dev/null
	cmake --install $(BUILD)/msgs > /dev/null
	touch $@

# --no-build-isolation: build with the pinned setuptools from requirements.txt.
$(EDITABLE_STAMP): $(REQS_STAMP) setup.py setup.cfg package.xml
	$(PY) -m pip install --quiet --no-deps --no-build-isolation -e .
	touch $@

lint: venv
	$(VENV)/bin/ruff check .
	$(VENV)/bin/mypy --strict prsm_health

test: venv lint
	timeout -k 30 $(TEST_RUN_TIMEOUT) $(VENV)/bin/pytest

# The ROS demo (prsm_health/ros/demo.py): the node, bags/sudden-jam played into it at twice its
# speed, the live monitor, then a summary beside the ground truth. Loopback only, its own
# domain id, and a hard time limit (the demo's own, then SIGTERM/SIGKILL from timeout).
DEMO_TIMEOUT ?= 300
demo: export ROS_DOMAIN_ID ?= 42
demo: venv
	timeout -k 10 $$(( $(DEMO_TIMEOUT) + 30 )) $(VENV)/bin/prsm-health demo --timeout $(DEMO_TIMEOUT)

# The bundled bags (bags/README.md): regenerate every one, then check that a second
# regeneration is byte-identical (cmp of metadata.yaml and the .mcap of each bag).
BAG_SCENES := nominal-downhole sudden-jam radial-misalignment stationary-hold accelerated-wear sensor-faults
BAG_CHECK_DIR := $(BUILD)/bags-check

bags: venv
	for scene in $(BAG_SCENES); do \
	  $(VENV)/bin/prsm-health simulate --scene $$scene --out bags/$$scene --force; \
	done
	$(MAKE) bags-check

bags-check: venv
	rm -rf $(BAG_CHECK_DIR)
	mkdir -p $(BAG_CHECK_DIR)
	for scene in $(BAG_SCENES); do \
	  $(VENV)/bin/prsm-health simulate --scene $$scene --out $(BAG_CHECK_DIR)/$$scene; \
	  cmp bags/$$scene/metadata.yaml $(BAG_CHECK_DIR)/$$scene/metadata.yaml; \
	  cmp bags/$$scene/$$scene.mcap $(BAG_CHECK_DIR)/$$scene/$$scene.mcap || { \
	    echo "bags-check: $$scene differs; on another kind of CPU than the one that wrote" \
	      "bags/ the truth's last bits do (bags/README.md): pytest" \
	      "test/scenes/test_bags.py compares what the bags say"; exit 1; }; \
	done
	@echo "bags: all $(words $(BAG_SCENES)) regenerate byte for byte"

clean:
	rm -rf $(VENV) $(BUILD) install log .pytest_cache .mypy_cache .ruff_cache *.egg-info
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
