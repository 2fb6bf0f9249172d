# valvemon: two commands on a machine that has only Python 3.11.
#   make demo   set up (virtual environment from the lockfile) and run the demo
#   make test   set up and run the whole test suite (what CI runs)
PYTHON ?= python3
UV_VERSION := 0.13.9
TOOLS := .tools
UV := $(TOOLS)/bin/uv
VENV := .venv
export PREFECT_SERVER_ANALYTICS_ENABLED := false
export PREFECT_HOME ?= $(CURDIR)/.prefect
export UV_LINK_MODE := copy

.PHONY: setup demo test bench clean

$(UV):
	$(PYTHON) -m venv $(TOOLS)
	$(TOOLS)/bin/pip install --quiet uv==$(UV_VERSION)

$(VENV)/.synced: $(UV) uv.lock pyproject.toml
	$(UV) sync --frozen --python $(PYTHON)
	touch $@

setup: $(VENV)/.synced

demo: setup
	$(VENV)/bin/valvemon demo

test: setup
	$(VENV)/bin/python -m pytest -n 2 --durations=15

bench: setup
	$(VENV)/bin/python bench/simulate.py

clean:
	rm -rf $(VENV) $(TOOLS) .prefect
