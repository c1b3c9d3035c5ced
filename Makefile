# Two commands on a fresh machine with python3.11, pip and make:  make demo  /  make test
# Everything is installed into .venv (torch 2.13.0 CPU, onnx, pytest, the ROS 2 PyPI wheels,
# and this package in editable mode).

PYTHON ?= $(or $(shell command -v python3.11 2>/dev/null),python3)
VENV   := .venv
STAMP  := $(VENV)/.installed.stamp
PYTEST_ARGS ?=
DEMO_ARGS ?=

.PHONY: venv demo test clean distclean

venv: $(STAMP)

# Re-runs only when a requirements or packaging file changed; pip on a populated venv is quick.
$(STAMP): requirements-dev.txt requirements-ros-wheels.txt setup.py setup.cfg package.xml
	@test -x $(VENV)/bin/python || { echo "creating $(VENV) with $(PYTHON)"; $(PYTHON) -m venv $(VENV); }
	$(VENV)/bin/python -m pip install -r requirements-dev.txt -e .
	@touch $@

# The live demo needs no dataset: a synthetic performer streams through the shipped model.
demo: venv
	$(VENV)/bin/motion-style demo $(DEMO_ARGS)

test: venv
	$(VENV)/bin/python -m pytest -q test $(PYTEST_ARGS)

clean:
	rm -rf build install log .pytest_cache *.egg-info
	find . -path ./$(VENV) -prune -o -name __pycache__ -type d -prune -exec rm -rf {} +

distclean: clean
	rm -rf $(VENV)
