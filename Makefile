# Two commands set everything up from nothing (Python 3.11, make, the package index):
#   make demo   - run the main job on the simulated rig
#   make test   - run the whole test suite (what CI runs)
# Everything installs into ./.venv, pinned by constraints.txt.

PYTHON ?= python3.11
VENV ?= .venv
PY := $(VENV)/bin/python
PIP := $(PY) -m pip
# Stamps record which dependency set is installed; they are rebuilt when the pins change.
RUNTIME_STAMP := $(VENV)/.stamp-runtime
DEV_STAMP := $(VENV)/.stamp-dev

.PHONY: demo test model venv dev bench clean-venv

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PIP) install --quiet --upgrade "pip>=24" wheel "setuptools>=69"

$(RUNTIME_STAMP): $(PY) pyproject.toml constraints.txt
	$(PIP) install --quiet -c constraints.txt -e .
	touch $@

$(DEV_STAMP): $(RUNTIME_STAMP) pyproject.toml constraints.txt
	$(PIP) install --quiet -c constraints.txt -e ".[dev,training]"
	touch $@

venv: $(RUNTIME_STAMP)
dev: $(DEV_STAMP)

demo: $(RUNTIME_STAMP)
	$(PY) -m firmware_host.demo --out out/demo

test: $(DEV_STAMP)
	$(PY) -m pytest -q

# Regenerate the shipped models from scratch (dataset, the human encoder's pretraining, training of
# the model and the baseline, ONNX export, int8 quantization, held-out evaluation, model card):
# 2 h 13 min measured end to end on 2 cores, ~2.1 h on a quiet machine, 56 min on a faster 2-core host
# (docs/training.md, "Lanes"; a GPU recipe that trains in ~13 min: "On a GPU machine";
# `--pretrain-set iterations=12000` for ~1.5 h).
model: $(DEV_STAMP)
	$(PY) -m training.pipeline --out models/

bench: $(DEV_STAMP)
	$(PY) benchmarks/bench_sim_render.py
	$(PY) benchmarks/bench_sim_rig.py
	$(PY) benchmarks/bench_protocol.py

clean-venv:
	rm -rf $(VENV)
