# The Makefile only calls the two CLIs (dtradar-data, dtradar-rl); every option lives in their --help.
PY      ?= .venv/bin/python
SCENE   ?= cubicle
VARIANT ?= all
NAME    ?= $(SCENE)/blueprint
ARGS    ?=
OSM     ?=
SCENES  ?=

.PHONY: setup test test-all dataset datasets list info verify cards publish pull train eval adapt offline logged offline-bench sweep paper bench bench-rt bench-rl bench-ray bench-diff bench-dynamic clean-venv

# One command on a fresh machine: a venv with the CPU build of torch, Sionna RT and a libLLVM >= 16 for it.
setup:
	python3 -m venv .venv
	$(PY) -m pip install --upgrade pip
	$(PY) -m pip install torch==2.13.0
	$(PY) -m pip install -e '.[all]'
	$(PY) -m dtradar_data check

test:
	$(PY) -m pytest -q

test-all:
	$(PY) -m pytest -q -m ''

# Ray-trace both variants (blueprint and dynamic) of a scene into the data root.
dataset:
	$(PY) -m dtradar_data build --scene $(SCENE) --variant $(VARIANT) $(if $(OSM),--osm $(OSM)) $(ARGS)

datasets:
	$(MAKE) dataset SCENE=cubicle
	$(MAKE) dataset SCENE=meeting

list:
	$(PY) -m dtradar_data list

info:
	$(PY) -m dtradar_data info $(NAME)

verify:
	$(PY) -m dtradar_data verify $(NAME)

cards:
	$(PY) -m dtradar_data cards $(ARGS)

publish:
	$(PY) -m dtradar_data publish $(NAME) $(ARGS)

pull:
	$(PY) -m dtradar_data pull $(NAME) $(ARGS)

train:
	$(PY) -m dtradar_rl train --scene $(SCENE) $(ARGS)

eval:
	$(PY) -m dtradar_rl eval --scene $(SCENE) $(ARGS)

# Offline RL with d3rlpy on logged transitions, e.g. make offline SCENE=cubicle ARGS="--algorithm cql"
offline:
	$(PY) -m dtradar_rl offline --scene $(SCENE) $(ARGS)

# A logged offline-RL dataset <scene>/blueprint/<behaviour> in the store (+ Minari copy), e.g.
# make logged SCENE=cubicle BEHAVIOUR=mixture ARGS="--checkpoint runs/cubicle/dqn/model.pt"
BEHAVIOUR ?= noisy-shortest
logged:
	$(PY) -m dtradar_rl log --scene $(SCENE) --behaviour $(BEHAVIOUR) $(ARGS)

# Offline-RL benchmark: d3rlpy CQL/BCQ/BC/DQN/DoubleDQN/NFQ x behaviour datasets x 3 seeds -> results/offline_bench/
offline-bench:
	$(PY) -m dtradar_rl offline-bench --scene $(SCENE) $(ARGS)

# Train + evaluate several scenes x seeds as Ray tasks (one per core), gathered into one table with mean and spread.
SEEDS   ?= 0 1 2
sweep:
	$(PY) -m dtradar_rl sweep $(if $(SCENES),--scenes $(SCENES)) --seeds $(SEEDS) $(ARGS)

# Twin update: fine-tune runs/$(SCENE)/dqn/model.pt on the dynamic twin, beside training from scratch (curve.png).
adapt:
	$(PY) -m dtradar_rl adapt --scene $(SCENE) $(ARGS)

# The paper's tables and figures from the built datasets into runs/paper/ (report.md + PNGs),
# e.g. make paper SCENES="cubicle meeting"; every option: python -m dtradar_rl paper --help
paper:
	$(PY) -m dtradar_rl paper $(if $(SCENES),--scenes $(SCENES)) $(ARGS)

bench: bench-rt bench-rl

bench-rt:
	$(PY) bench/bench_rt.py $(ARGS)

bench-rl:
	$(PY) bench/bench_rl.py $(ARGS)

# Differential vs full re-trace of each dynamic twin, side by side (time, agreement) -> results/bench_differential_*
bench-diff:
	$(PY) bench/bench_differential.py $(if $(SCENES),--scenes $(SCENES)) $(ARGS)

# Navigation under change: the planner beside the memory agents, and twin-update curves -> results/bench_dynamic*
bench-dynamic:
	$(PY) bench/bench_dynamic.py $(if $(SCENES),--scenes $(SCENES)) $(ARGS)

# Serial vs Ray tracing, side by side in one run (cells/s and the speed-up on this machine's cores).
bench-ray:
	$(PY) bench/bench_ray.py $(ARGS)
