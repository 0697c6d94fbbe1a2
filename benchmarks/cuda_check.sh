#!/usr/bin/env bash
# GPU check of the CUDA path (issue 20): run from the repository root on a machine with a GPU and
# the project's packages importable. Writes its logs and synth_cuda.md under OUT (default out/cuda).
#   1. the tests that compare CUDA with the CPU (skipped without a GPU elsewhere)
#   2. `datagen synth --num 100 --iters 500` on a real mesh (OBJ, default pybullet's mug), twice:
#      wall time end to end (the second run on a warm objects cache) and run-to-run identity
#   3. the default job's shards on CUDA, in-process (benchmarks/cuda_shards.py: no Ray needed)
#   4. bench-synth on CUDA with the throughput-by-batch-size table
# Each step has its own time limit, so one hang does not take the rest with it.
OUT=${1:-out/cuda}; OBJ=${OBJ:-$(python3 -c "import pybullet_data as p; print(p.getDataPath())")/objects/mug.obj}
mkdir -p "$OUT"; export PYTHONUNBUFFERED=1
T0=$(date +%s); step() { echo "[t+$(( $(date +%s) - T0 ))s] $*"; }
nvidia-smi -L
step "1. CUDA tests"
timeout 150 python3 -m pytest -q -p no:cacheprovider tests/synth/test_device.py tests/objects/test_sdf.py \
  tests/hands/test_kinematics.py tests/wrench/test_gws.py tests/synth/test_target.py -rs >"$OUT/pytest_cuda.log" 2>&1
tail -3 "$OUT/pytest_cuda.log"
step "2. datagen synth --num 100 --iters 500 on $OBJ (CUDA; the first run also processes the mesh)"
for r in 1 2 3; do /usr/bin/time -f "wall_s=%e" timeout 300 python3 -m datagen.cli synth --object "$OBJ" --num 100 \
  --iters 500 --device cuda --out "$OUT/synth_$r.parquet" 2>&1 | grep -E "wrote|wall_s|error"; done
python3 -c "import pyarrow.parquet as pq; a, b = (pq.read_table('$OUT/synth_%d.parquet' % i) for i in (2, 3)); print('identical runs:', a.equals(b))"
step "3. the default job's shards on CUDA, no Ray"
timeout 300 python3 -m benchmarks.cuda_shards "$OUT/job" 6 >"$OUT/shards.log" 2>&1; grep -E "^\{|^shards|^failure" "$OUT/shards.log"
step "4. bench-synth on CUDA"
timeout 200 python3 -m benchmarks.bench_synth --device cuda --repeats 3 --batches 100,1000,4000 --out "$OUT/synth_cuda.md" | tail -6
step done
