# The job targets call the two CLIs (python -m dtradar_data, python -m dtradar_rl); the bench targets run the scripts
# in bench/ (python bench/<name>.py); setup, test, lint, format and docs run pip, pytest, ruff and mkdocs. Every
# option of a CLI or a script is on its --help and passes through ARGS="...".
PY      ?= .venv/bin/python
SCENE   ?= cubicle
VARIANT ?= all
NAME    ?= $(SCENE)/blueprint
ARGS    ?=
OSM     ?=
SCENES  ?=

.PHONY: help setup test test-all lint format docs dataset datasets list info verify cards publish pull train eval adapt solve offline log logged offline-bench sweep paper bench bench-rt bench-radiomap bench-transmitters bench-tx-shift bench-rl bench-ray bench-diff bench-moving bench-dynamic bench-latency bench-threads bench-nav bench-radio bench-tabular bench-offline-speed bench-gpu gpu-pack results-pages

# List the targets, each with the first line of the comment above it (a make variable shown as <name>); `make` alone does the same.
help:
	@awk '/^# / { if (c == "") c = substr($$0, 3); next } /^[a-z][a-z-]*:/ { n = $$1; sub(/:.*/, "", n); while (match(c, /\$$\([A-Z_]+\)/)) c = substr(c, 1, RSTART - 1) "<" tolower(substr(c, RSTART + 2, RLENGTH - 3)) ">" substr(c, RSTART + RLENGTH); printf "  %-20s %s\n", n, c; c = ""; next } { c = "" }' $(MAKEFILE_LIST)

# One command on a fresh machine: a venv with the CPU build of torch, Sionna RT and a libLLVM >= 16 for it.
setup:
	python3 -m venv .venv
	$(PY) -m pip install --upgrade pip
	$(PY) -m pip install torch==2.13.0
	$(PY) -m pip install -e '.[all]'
	$(PY) -m dtradar_data check

# The default checks: lint and format check (ruff), the docs site (mkdocs --strict), then the tests.
test: lint docs
	$(PY) -m pytest -q

# ruff: lint rules and the format check configured in pyproject.toml.
lint:
	$(PY) -m ruff check .
	$(PY) -m ruff format --check .

# Rewrite files in ruff's format and apply ruff's safe fixes.
format:
	$(PY) -m ruff format .
	$(PY) -m ruff check --fix .

# The documentation site (mkdocs + mkdocstrings, offline) into site/; warnings (dead links, missing modules) fail.
docs:
	$(PY) -m mkdocs build --strict --quiet

# Lint, docs and every test, the slow ones included (worker processes, Ray sessions): what CI runs.
test-all: lint docs
	$(PY) -m pytest -q -m ''

# Ray-trace both variants (blueprint and dynamic) of a scene into the data root (VARIANT=moving: its moving twin).
dataset:
	$(PY) -m dtradar_data build --scene $(SCENE) --variant $(VARIANT) $(if $(OSM),--osm $(OSM)) $(ARGS)

# Both indoor twins (cubicle and meeting), both variants.
datasets:
	$(MAKE) dataset SCENE=cubicle
	$(MAKE) dataset SCENE=meeting

# Every dataset in the data root, with its versions.
list:
	$(PY) -m dtradar_data list

# One dataset's card summary, e.g. make info NAME=cubicle/dynamic.
info:
	$(PY) -m dtradar_data info $(NAME)

# Re-hash a stored dataset's files against its version (exit 1 when damaged).
verify:
	$(PY) -m dtradar_data verify $(NAME)

# Re-render the committed dataset cards under cards/.
cards:
	$(PY) -m dtradar_data cards $(ARGS)

# Push a stored version to the Hugging Face Hub, e.g. make publish NAME=cubicle/blueprint ARGS="--repo you/dtradar".
publish:
	@if [ "$(origin NAME)" = "file" ]; then echo "error: make publish uploads one dataset and needs its name" >&2; echo "  how to fix: make publish NAME=<scene>/<variant> ARGS=\"--repo <you>/<repo>\" (make list shows what is built)" >&2; exit 2; fi
	$(PY) -m dtradar_data publish $(NAME) $(ARGS)

# Pull a version from the Hugging Face Hub into the data root.
pull:
	$(PY) -m dtradar_data pull $(NAME) $(ARGS)

AGENT ?= radio-filter
MOVING_ARGS ?= --sense-radius 4 --wait-action --clock sincos --mover-penalty 4
# Build the default agent (radio filter, honest sensing) on $(SCENE)'s blueprint -> runs/$(SCENE)/agent/agent.json.
# A localisation filter over the blueprint's radio fingerprints acting on exact distances, from honest sensing (own
# cell's radio, proximity, odometry; never its position). AGENT=dqn, or ARGS naming a --preset, trains the learnt
# DQN instead -> runs/$(SCENE)/dqn/model.pt (privileged: its observation holds the robot's x, y; ARGS="--preset
# paper" etc.); VARIANT=moving trains that DQN among the movers of
# the moving twin with $(MOVING_ARGS) -> runs/$(SCENE)/dqn-moving/model.pt: the best measured among movers
# (docs/explanation/learnt-agents.md, "Among movers"): the cells up to 4 away sensed, a wait action, the
# schedule's phase, a 4x mover penalty, the margin loss towards the shortest paths in time, twice the static budget.
train:
	$(if $(or $(filter dqn,$(AGENT)),$(filter moving,$(VARIANT)),$(findstring --preset,$(ARGS))),$(PY) -m dtradar_rl train --scene $(SCENE) $(if $(filter moving,$(VARIANT)),--variant moving $(MOVING_ARGS) --out runs/$(SCENE)/dqn-moving) $(ARGS),$(PY) -m dtradar_rl agent --scene $(SCENE) $(ARGS))

# Evaluate the default agent on the blueprint and dynamic twins, beside the privileged DQN and the planner.
# Under realistic receiver noise, each row naming its sensing; VARIANT=moving
# adds the moving twin, and the agent trained among movers (runs/$(SCENE)/dqn-moving) when there is one -> runs/$(SCENE)/eval-moving
eval:
	$(PY) -m dtradar_rl eval --scene $(SCENE) $(if $(filter moving,$(VARIANT)),--variants blueprint dynamic moving) $(ARGS)
	$(if $(and $(filter moving,$(VARIANT)),$(wildcard runs/$(SCENE)/dqn-moving/model.pt)),$(PY) -m dtradar_rl eval --scene $(SCENE) --variants moving --checkpoint runs/$(SCENE)/dqn-moving/model.pt --out runs/$(SCENE)/eval-moving --no-planner $(ARGS))

# Offline RL with d3rlpy on a logged dataset, evaluated on the blueprint and dynamic twins.
# --logged NAME, else <scene>/blueprint/<behaviour>, logged or reused; e.g. make offline SCENE=cubicle ARGS="--algorithm cql"
offline:
	$(PY) -m dtradar_rl offline --scene $(SCENE) $(ARGS)

# The exact solution of $(SCENE)'s twins and its greedy policy's success and SPL -> results/solve/$(SCENE)/
# V*/Q* for every (cell, target) under the geodesic and paper rewards (cached in the data root), 500 evaluation pairs.
solve:
	$(PY) -m dtradar_rl solve --scene $(SCENE) $(ARGS)

BEHAVIOUR ?= noisy-shortest
# Log a behaviour policy or a dataset family as an offline-RL dataset <scene>/blueprint/<behaviour> (+ Minari copy).
# e.g. make log SCENE=cubicle BEHAVIOUR=mixture ARGS="--checkpoint runs/cubicle/dqn/model.pt" (a memoryless agent:
# make train SCENE=cubicle AGENT=dqn ARGS="--preset tuned"). Dataset families (D4RL's names, no checkpoint needed): BEHAVIOUR=
# random, expert, medium, medium-replay or mixed, and OGBench's navigate, stitch or explore; BEHAVIOUR=all logs the
# eight (docs/reference/logged-datasets.md).
log:
	$(PY) -m dtradar_rl log --scene $(SCENE) --behaviour $(BEHAVIOUR) $(ARGS)

# The old name of `make log` (the CLI's name): refused, naming the new one.
logged:
	@echo "error: make logged is now make log (the CLI's name: python -m dtradar_rl log)" >&2
	@echo "  how to fix: make log SCENE=$(SCENE) BEHAVIOUR=$(BEHAVIOUR) $(ARGS)" >&2
	@exit 2

# Offline-RL benchmark: d3rlpy CQL/BCQ/BC/DQN/DoubleDQN/NFQ x behaviour datasets x 3 seeds -> results/offline_bench/
offline-bench:
	$(PY) -m dtradar_rl offline-bench --scene $(SCENE) $(ARGS)

SEEDS   ?= 0 1 2
# Train + evaluate several scenes x seeds as Ray tasks (one per core), gathered into one table with mean and spread.
sweep:
	$(PY) -m dtradar_rl sweep $(if $(SCENES),--scenes $(SCENES)) --seeds $(SEEDS) $(ARGS)

# Twin update: fine-tune runs/$(SCENE)/dqn/model.pt on the dynamic twin, beside training from scratch (curve.png).
adapt:
	$(PY) -m dtradar_rl adapt --scene $(SCENE) $(ARGS)

# The paper's tables and figures from the built datasets -> runs/paper/ (report.md + PNGs).
# e.g. make paper SCENES="cubicle meeting"; every option: python -m dtradar_rl paper --help
paper:
	$(PY) -m dtradar_rl paper $(if $(SCENES),--scenes $(SCENES)) $(ARGS)

# Tabular Q-learning and Dyna-Q beside the DQN at equal env steps -> results/bench_tabular.*
# Learning curves, fingerprint ambiguity, localisation cost.
bench-tabular:
	$(PY) bench/bench_tabular.py $(if $(SCENES),--scenes $(SCENES)) $(ARGS)

# Both main benchmarks: ray tracing and navigation.
bench: bench-rt bench-rl

# Ray-tracing speed and accuracy against a reference trace -> results/bench_rt.*
bench-rt:
	$(PY) bench/bench_rt.py $(ARGS)

# Per-cell PathSolver gain against Sionna's RadioMapSolver, each ablation side by side -> results/bench_radiomap/
bench-radiomap:
	$(PY) bench/bench_radiomap.py --scene $(SCENE) $(ARGS)

# Tracing time and memory per transmitter: a twin with its first 1..N transmitters, side by side -> results/bench_transmitters.*
bench-transmitters:
	$(PY) bench/bench_transmitters.py $(ARGS)

# What a dynamic twin changes per transmitter and what it costs the agents and the planner -> results/bench_transmitter_shift.*
bench-tx-shift:
	$(PY) bench/bench_transmitter_shift.py $(ARGS)

# Our DQN against Stable-Baselines3 DQN on the same twins, side by side -> results/bench_rl.*
bench-rl:
	$(PY) bench/bench_rl.py $(ARGS)

# Differential vs full re-trace of each dynamic twin, side by side (time, agreement) -> results/bench_differential_*
bench-diff:
	$(PY) bench/bench_differential.py $(if $(SCENES),--scenes $(SCENES)) $(ARGS)

# A moving twin's snapshots against a full trace of each (time, agreement, seed floor) -> results/bench_moving_*
bench-moving:
	$(PY) bench/bench_moving.py $(if $(SCENES),--scenes $(SCENES)) $(ARGS)

# Navigation under change: the planner beside the memory agents, and twin-update curves -> results/bench_dynamic*
bench-dynamic:
	$(PY) bench/bench_dynamic.py $(if $(SCENES),--scenes $(SCENES)) $(ARGS)

# Serial vs Ray tracing, side by side in one run (cells/s and the speed-up on this machine's cores).
bench-ray:
	$(PY) bench/bench_ray.py $(ARGS)

# One robot's decision time: p50/p99 with 1 and 2 torch threads, idle and beside a busy process -> results/bench_latency_*
bench-latency:
	$(PY) bench/bench_latency.py --scene $(SCENE) $(ARGS)

# The training loop's torch threads: 1 vs 2, idle and beside a busy process -> results/bench_threads_$(SCENE).*
bench-threads:
	$(PY) bench/bench_threads.py --scene $(SCENE) $(ARGS)

# The default agent, SB3 DQN and the planner on every twin, with and without noise and a tx pose error -> results/bench_nav.*
bench-nav:
	$(PY) bench/bench_nav.py $(if $(SCENES),--scenes $(SCENES)) $(ARGS)

# What the radio contributes: the default agent with each sensing and noise level on every twin -> results/bench_radio.*
# Sensings radio, without each feature group, RSSI, no radio; noise none, realistic, 2x; localisation error plots.
bench-radio:
	$(PY) bench/bench_radio.py $(if $(SCENES),--scenes $(SCENES)) $(ARGS)

# GPU figures (tracing, batched env, training; CUDA beside the CPU) -> results/bench_gpu.*.
# On a GPU machine run bash bench/gpu.sh after make gpu-pack here.
bench-gpu:
	$(PY) bench/bench_gpu.py $(ARGS)

# Copy the twins bench/gpu.sh reads (dallas-q3, cubicle) into .gpu_data/, which travels with the working tree.
gpu-pack:
	mkdir -p .gpu_data/datasets
	for t in dallas-q3 cubicle; do cp -r "$$($(PY) -c 'from dtradar_data.core.layout import data_root; print(data_root())')/datasets/$$t" .gpu_data/datasets/; done

# d3rlpy updates/s per algorithm: logging, sampler, threads, epochs, evaluators, worker processes -> results/bench_offline_speed.*
bench-offline-speed:
	$(PY) bench/bench_offline_speed.py --scene $(SCENE) $(ARGS)

# Re-render the marked tables of docs/results/*.md from the benchmarks' JSON under results/ (ARGS="--check": exit 1 if stale).
results-pages:
	$(PY) tools/results_pages.py $(ARGS)
