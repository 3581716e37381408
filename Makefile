# The README's commands. `make test` prepares the environment first (quick when it is ready).
VENV ?= .venv
PY := $(VENV)/bin/python

.PHONY: setup test demo eval clean

setup:
	bash scripts/setup.sh

test: setup
	$(PY) -m pytest -q test

demo: setup
	$(VENV)/bin/sparse-body eval --estimator reference --sensors four_point

eval: demo

clean:
	rm -rf build $(VENV)
