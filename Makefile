# The README's commands. `make test` prepares the environment first (quick when it is ready).
VENV ?= .venv
PY := $(VENV)/bin/python

.PHONY: setup setup-test setup-train setup-dev test test-train test-busy demo eval bench fuzz cards train-lobstr train-dragposer train-dtp train-avatarjlm train-forecast clean

# The runtime (nodes, offline tools, demo: no torch); with the test suite's tools (--test);
# with training as well (--train: PyPI's torch and its CUDA libraries, about 5 GB more).
setup:
	bash scripts/setup.sh

setup-test:
	bash scripts/setup.sh --test

setup-train:
	bash scripts/setup.sh --train

setup-dev: setup-train

# The suite without training: every method's inference, nodes, launch, offline tools (no torch).
test: setup-test
	$(PY) -m pytest -q -rs -m "not train" test

# The tests that train (a short run of each method's trainer) or compare with torch.
test-train: setup-train
	$(PY) -m pytest -q -rs -m train test

# The suite on a busy machine: one CPU-burning process per core runs beside it.
test-busy: setup-test
	bash scripts/busy.sh $(PY) -m pytest -q -rs -m "not train" test

demo: setup
	$(VENV)/bin/sparse-body demo

eval: setup
	$(PY) -m sparse_body.methods eval | while read method sensors; do \
	  $(VENV)/bin/sparse-body eval --estimator $$method --sensors $$sensors || exit 1; done

bench: setup-train
	$(VENV)/bin/sparse-body bench
	for m in $$($(PY) -m sparse_body.methods benched); do $(VENV)/bin/sparse-body bench --runtime $$m || exit 1; done

# A million generated inputs into each parser of outside input: the serial stream, VMC
# datagrams, /tf messages through the TF ingest, BVH and ASF/AMC motion files, sensor
# configuration and calibration YAML, a robot's URDF and mapping YAML (and the URDF as a peer's
# robot_description).
fuzz: setup-test
	for target in serial vmc tf bvh asf_amc yaml robot; do $(VENV)/bin/python -m sparse_body.apps.fuzz $$target 1000000 || exit 1; done

# The release of the test-split tables: every shipped model measured again on the test split
# (models/<model>.eval.json, each run's per-clip figures) and its card rendered from that; the
# only command that reads the test split. `sparse-body train M --render-only` renders a card
# from its measured file without measuring.
cards: setup-train
	for m in $$($(PY) -m sparse_body.methods trainable); do $(VENV)/bin/sparse-body train $$m --card-only || exit 1; done

# Retrain the shipped LoBSTr model (11,848 steps: about 50 minutes on 2 CPU cores) and rewrite its model card.
train-lobstr: setup-train
	$(VENV)/bin/sparse-body train lobstr --config small

# Retrain the shipped DragPoser models: the pose VAE, then its temporal predictor (30 + 30
# minutes on 2 CPU cores), and rewrite the model card.
train-dragposer: setup-train
	$(VENV)/bin/sparse-body train dragposer --config small

# Retrain the shipped DTP models: the lookahead one, then the online one (pre-training and
# occlusion fine-tuning, about 45 minutes each on 2 CPU cores), and rewrite the model card
# (which evaluates them; the online model's run does).
train-dtp: setup-train
	$(VENV)/bin/sparse-body train dtp --config lookahead --no-card
	$(VENV)/bin/sparse-body train dtp --config small

# Retrain the shipped AvatarJLM models: the three- and four-point ones side by side, a core
# each (88 minutes; and 3,965 steps, 76 minutes on the 2-core developer machine), then one card
# for both (which evaluates them).
train-avatarjlm: setup-train
	$(VENV)/bin/sparse-body train avatarjlm --config four_point --threads 1 --no-card & \
	$(VENV)/bin/sparse-body train avatarjlm --config small --threads 1 --no-card; wait
	$(VENV)/bin/sparse-body train avatarjlm --card-only

# Retrain predict_ahead's learned root forecast (six-point ik's estimate of the train split,
# chosen on the validation people; about 2 minutes on 2 CPU cores) and rewrite its card.
train-forecast: setup-train
	$(VENV)/bin/python -m sparse_body.train.forecast

clean:
	rm -rf build $(VENV)
