# Two commands set everything up from nothing (Python 3.11, make, the package index):
#   make demo   - run the main job on the simulated rig
#   make test   - run the whole test suite (what CI runs)
# Everything installs into ./.venv, pinned by constraints.txt.

PYTHON ?= python3.11
VENV ?= .venv
PY := $(VENV)/bin/python
PIP := $(PY) -m pip
# pip (26 on) passes on what the build backend warns of for a local folder, and setuptools warns on every editable
# install: "Editable installation ... Please be careful with folders in your working directory with the same name as
# your package". Here those folders are the packages themselves, so that note alone is filtered out, by its text.
PIP_EDITABLE := PYTHONWARNINGS="ignore:Editable installation" $(PIP)
# Stamps record which dependency set is installed; they are rebuilt when the pins change.
RUNTIME_STAMP := $(VENV)/.stamp-runtime
DEV_STAMP := $(VENV)/.stamp-dev

.PHONY: demo test model painter painter-gpu venv dev bench clean-venv

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PIP) install --quiet --upgrade "pip>=24" wheel "setuptools>=77"

$(RUNTIME_STAMP): $(PY) pyproject.toml constraints.txt
	$(PIP_EDITABLE) install --quiet -c constraints.txt -e .
	touch $@

$(DEV_STAMP): $(RUNTIME_STAMP) pyproject.toml constraints.txt
	$(PIP_EDITABLE) install --quiet -c constraints.txt -e ".[dev,training]"
	touch $@

venv: $(RUNTIME_STAMP)
dev: $(DEV_STAMP)

demo: $(RUNTIME_STAMP)
	$(PY) -m firmware_host.demo --out out/demo

test: $(DEV_STAMP)
	$(PY) -m pytest -q

# Regenerate the models from scratch (dataset, the human encoder's pretraining, training of the model
# and the baseline, ONNX export, int8 quantization, skeleton prior, held-out evaluation, model card).
# The recipe follows the machine (`--recipe auto`): where torch sees a GPU, the shipped (tenth) model's,
# ~25 min of one H100 (and ~30 min on two cores for its two-network skeleton prior);
# on CPU the two-core recipe (the trunk at 128x128, 44000 pretraining steps in bfloat16 where the CPU has it, the
# first 17600 at 64x64; a skeleton prior of two networks). Both train the prior as the shipped one was, bodies
# at any angle (--tilt-share 0.3 --tilt-mode body; docs/training.md, "Bodies at any angle"). The two-core
# recipe: about 1 h 56 min from nothing on a fast AVX-512 2-core host by its stages' measured times, about
# 2 h 45 min on session 35's EPYC (its first three stages timed), well over two hours on an Intel Xeon host,
# about 4 h on the slowest seen
# (docs/training.md, "The tenth model", "Progressive resizing in the two-core pretraining" and "Two prior
# networks in the cpu recipe").
# RECIPE=cpu or RECIPE=gpu picks one.
RECIPE ?= auto
model: $(DEV_STAMP)
	$(PY) -m training.pipeline --out models/ --recipe $(RECIPE)

# The novel view's learnt painter (models/ghnerf/novel_painter.onnx) for the model in models/, on the dataset
# make model made: the device's joints of 2048 training and 256 held-out scenes, the painter's inputs over their
# body proxies (without the light fit, which the runtime's painter does not read), 70 minutes of training at one
# thread with the fog around the subject taught as background (session 31's painter), export to fp32 and int8
# with parity checks, the model card: 1 h 24 min on two cores, timed end to end (docs/training.md, "The
# painter and the fog").
# PAINTER_MODELS=<folder> reads that folder's model and writes the painter and its card entry there instead.
PAINTER_DATA ?= data/edge128
PAINTER_RUNS ?= runs/painter
PAINTER_MODELS ?= models
painter: $(DEV_STAMP)
	@test -f $(PAINTER_DATA)/dataset.json || { echo "make painter: no dataset in $(PAINTER_DATA) (no dataset.json):" \
	    "\`make model\` makes it there first (no GPU needed), or set PAINTER_DATA=<a dataset folder>;" \
	    "\`make painter-gpu\` generates its own" >&2; exit 1; }
	$(PY) -m training.device_joints --data $(PAINTER_DATA) --split train --limit 2048 --model $(PAINTER_MODELS)/ghnerf \
	    --out $(PAINTER_RUNS)/joints_train.npz
	$(PY) -m training.device_joints --data $(PAINTER_DATA) --split val --limit 256 --model $(PAINTER_MODELS)/ghnerf \
	    --out $(PAINTER_RUNS)/joints_val.npz
	$(PY) -m training.learnt_fill cache --data $(PAINTER_DATA) --split train --limit 2048 --no-relit \
	    --model $(PAINTER_MODELS)/ghnerf/ghnerf.pt --joints $(PAINTER_RUNS)/joints_train.npz --out $(PAINTER_RUNS)/fill_train.npz
	$(PY) -m training.learnt_fill cache --data $(PAINTER_DATA) --split val --limit 256 --no-relit \
	    --model $(PAINTER_MODELS)/ghnerf/ghnerf.pt --joints $(PAINTER_RUNS)/joints_val.npz --out $(PAINTER_RUNS)/fill_val.npz
	$(PY) -m training.learnt_fill train --train-cache $(PAINTER_RUNS)/fill_train.npz --val-cache $(PAINTER_RUNS)/fill_val.npz \
	    --out $(PAINTER_RUNS)/net --threads 1 --set net.width=16 --set batch=8 --set steps=1000000 --set max_seconds=4200 \
	    --set net.shown_input=true --set net.relit_input=false --set around_weight=0.03
	$(PY) -m training.learnt_fill export --net $(PAINTER_RUNS)/net/fill_net.pt \
	    --out $(PAINTER_MODELS)/ghnerf/novel_painter.onnx --val-cache $(PAINTER_RUNS)/fill_val.npz \
	    --calib-cache $(PAINTER_RUNS)/fill_train.npz --card-dir $(PAINTER_MODELS)

# The same painter trained on a GPU machine (training/painter_gpu.sh: the data, the device's joints and the caches
# at all cores, then 270 s of one GPU at batches of 32), exported here: how the shipped painter was made since
# session 38 (about 7 minutes of a 16-core H200 machine, export 1 min; docs/training.md, "The painter on a GPU").
# PAINTER_WIDTH=32 makes the wider painter measured there: +0.2 dB masked for +8 ms per painted view, 14 MB.
PAINTER_WIDTH ?= 16
painter-gpu: $(DEV_STAMP)
	WIDTHS=$(PAINTER_WIDTH) PYTHON=$(PY) MODELS=$(PAINTER_MODELS) \
	    bash training/painter_gpu.sh $(PAINTER_RUNS)/gpu $(PAINTER_RUNS)/gpu 2048 270
	$(PY) -m training.learnt_fill export --net $(PAINTER_RUNS)/gpu/w$(PAINTER_WIDTH)/fill_net.pt \
	    --out $(PAINTER_MODELS)/ghnerf/novel_painter.onnx --val-cache $(PAINTER_RUNS)/gpu/fill_val.npz \
	    --calib-cache $(PAINTER_RUNS)/gpu/fill_train.npz --card-dir $(PAINTER_MODELS)

bench: $(DEV_STAMP)
	$(PY) benchmarks/bench_sim_render.py
	$(PY) benchmarks/bench_sim_rig.py
	$(PY) benchmarks/bench_protocol.py

clean-venv:
	rm -rf $(VENV)
