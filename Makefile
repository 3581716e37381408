# The README's commands. `make test` prepares the environment first (quick when it is ready).
VENV ?= .venv
PY := $(VENV)/bin/python

.PHONY: setup test demo eval bench clean

setup:
	bash scripts/setup.sh

test: setup
	$(PY) -m pytest -q test

demo: setup
	$(VENV)/bin/sparse-body demo

eval: setup
	$(VENV)/bin/sparse-body eval --estimator reference --estimator ik --sensors six_point

bench: setup
	$(VENV)/bin/sparse-body bench

clean:
	rm -rf build $(VENV)
