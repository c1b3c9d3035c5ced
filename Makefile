# Two commands on a fresh machine with python3.11, pip and make:  make demo  /  make test
# Everything is installed into .venv (torch 2.13.0 CPU, onnx, pytest, the ROS 2 PyPI wheels,
# and this package in editable mode). `make test-runtime` runs the tests in .venv-runtime instead:
# the package as `pip install .` installs it, without torch (the tests of training and the torch
# models skip there, each with its reason).
# Where ../shared/ros/install.sh exists (beside this repository), both venvs also get the real ROS 2
# launch and command-line tools (ros2, launch_test) that the launch and CLI tests run.

PYTHON ?= $(or $(shell command -v python3.11 2>/dev/null),python3)
VENV   := .venv
STAMP  := $(VENV)/.installed.stamp
RT_VENV  := .venv-runtime
RT_STAMP := $(RT_VENV)/.installed.stamp
PYTEST_ARGS ?=
# Resolved from this Makefile's folder, so `make -C path/to/repo` finds it too.
ROS_TOOLS := $(wildcard $(abspath $(dir $(lastword $(MAKEFILE_LIST)))../shared/ros/install.sh))
DEMO_ARGS ?=

.PHONY: venv demo test test-runtime clean distclean

venv: $(STAMP)

# Re-runs only when a requirements or packaging file changed; pip on a populated venv is quick.
$(STAMP): requirements-dev.txt requirements-test.txt requirements-ros-wheels.txt setup.py setup.cfg package.xml $(ROS_TOOLS)
	@test -x $(VENV)/bin/python || { echo "creating $(VENV) with $(PYTHON)"; $(PYTHON) -m venv $(VENV); }
	$(VENV)/bin/python -m pip install -r requirements-dev.txt -e .
	$(if $(ROS_TOOLS),$(ROS_TOOLS) $(VENV)/bin/python)
	$(VENV)/bin/motion-style warmup
	@touch $@

# The live demo needs no dataset: a synthetic performer streams through the shipped model.
demo: venv
	$(VENV)/bin/motion-style demo $(DEMO_ARGS)

test: venv
	$(VENV)/bin/python -m pytest -q test $(PYTEST_ARGS)

# Not editable: the package is reinstalled whenever a file of it changed. The tests run from test/
# so that they import the installed package (and its installed share/ files), not the source tree.
$(RT_STAMP): requirements-test.txt requirements-ros-wheels.txt setup.py setup.cfg package.xml $(ROS_TOOLS) \
		$(shell find motion_style_ros launch config models urdf resource -type f -not -name '*.pyc')
	@test -x $(RT_VENV)/bin/python || { echo "creating $(RT_VENV) with $(PYTHON)"; $(PYTHON) -m venv $(RT_VENV); }
	$(RT_VENV)/bin/python -m pip install -r requirements-test.txt -r requirements-ros-wheels.txt .
	$(if $(ROS_TOOLS),$(ROS_TOOLS) $(RT_VENV)/bin/python)
	@if $(RT_VENV)/bin/python -c "import torch" 2>/dev/null; then \
		echo "$(RT_VENV) has torch: the runtime's tests must run without it"; exit 1; fi
	$(RT_VENV)/bin/motion-style warmup
	@touch $@

test-runtime: $(RT_STAMP)
	cd test && ../$(RT_VENV)/bin/python -m pytest -q . $(PYTEST_ARGS)

clean:
	rm -rf build install log .pytest_cache *.egg-info
	find . -path ./$(VENV) -prune -o -name __pycache__ -type d -prune -exec rm -rf {} +

distclean: clean
	rm -rf $(VENV) $(RT_VENV)
