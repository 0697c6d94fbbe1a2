#!/usr/bin/env bash
# GPU check of the CUDA path (issue 20): run from the repository root on a machine with a GPU and
# the project's packages importable. Writes its logs and synth_cuda.md under OUT (default out/cuda).
#   1. the tests that compare CUDA with the CPU (skipped without a GPU elsewhere)
#   2. `datagen synth --num 100 --iters 500` on a real mesh (OBJ, default pybullet's mug), three
#      times: wall time end to end (the first run also processes the mesh) and run-to-run identity
#   3. the default job's shards in-process (benchmarks/cuda_shards.py: no Ray needed), then a
#      GPU-sized job: BIG objects in one shard (one synthesis batch) with CPUS evaluation processes
#   4. bench-synth with the throughput-by-batch-size table
#   5. a whole job on the real-object set (issue 47): `datagen run` on Ray where Ray imports (else
#      its shards in-process), validated grasps per GPU-hour, seconds per stage and the GPU's
#      utilisation (nvidia-smi sampled every 0.5 s while it runs: mean and share of samples > 50%)
# Each step has its own time limit, and all together stop by BUDGET seconds (default 520) after
# the start, so one hang does not take the rest with it and a lease is not overrun.
# DEVICE=cpu SMOKE=1 runs the same steps small and on the CPU (a check of this script itself).
# Where the GPU machine cannot install packages, carry wheels of the project's dependencies
# (pip download --platform manylinux... for its Python) and the hand asset folders, and put them
# on PYTHONPATH before running this (benchmarks/results/cuda_check.md says what was carried).
OUT=${1:-out/cuda}; DEVICE=${DEVICE:-cuda}; BUDGET=${BUDGET:-520}; STEPS=${STEPS:-12345}  # e.g. STEPS=5: the job only
OBJ=${OBJ:-$(python3 -c "import pybullet_data as p; print(p.getDataPath())")/objects/mug.obj}
HAND=${HAND:-shadow}
if [ -n "$SMOKE" ]; then NUM=8; ITERS=50; OBJECTS=1; BIG=2; CPUS=2; REAL=1
  BENCH="--grasps 16 --iters 50 --repeats 1 --iters-k1e4 5 --batches 16"
else NUM=100; ITERS=500; OBJECTS=6; BIG=${BIG:-16}; CPUS=${CPUS:-14}; REAL=${REAL:-10}
  BENCH=${BENCH:---repeats 1 --batches 100,1000,4000}; fi
mkdir -p "$OUT"; export PYTHONUNBUFFERED=1
T0=$(date +%s); step() { echo "[t+$(( $(date +%s) - T0 ))s] $*"; }
# lim S: S seconds, or what is left of the budget if less (at least 1)
lim() { local left=$(( BUDGET - ($(date +%s) - T0) )); [ "$left" -lt "$1" ] && echo $(( left > 1 ? left : 1 )) || echo "$1"; }
nvidia-smi -L 2>/dev/null || echo "no nvidia-smi"
if [[ $STEPS == *1* ]]; then
step "1. CUDA tests"
timeout "$(lim 150)" python3 -m pytest -q -p no:cacheprovider tests/synth/test_device.py tests/objects/test_sdf.py \
  tests/hands/test_kinematics.py tests/wrench/test_gws.py tests/synth/test_target.py -rs >"$OUT/pytest_cuda.log" 2>&1
tail -3 "$OUT/pytest_cuda.log"
fi
if [[ $STEPS == *2* ]]; then
step "2. datagen synth --num $NUM --iters $ITERS on $OBJ ($DEVICE)"
for r in 1 2 3; do /usr/bin/time -f "wall_s=%e" timeout "$(lim 100)" python3 -m datagen.cli synth --object "$OBJ" --num $NUM \
  --iters $ITERS --device $DEVICE --out "$OUT/synth_$r.parquet" 2>&1 | grep -E "wrote|wall_s|error"; done
python3 -c "import pyarrow.parquet as pq; a, b = (pq.read_table('$OUT/synth_%d.parquet' % i) for i in (2, 3)); print('identical runs:', a.equals(b))"
fi
if [[ $STEPS == *3* ]]; then
step "3. the default job's shards (on CUDA wherever there is a GPU), no Ray"
rm -rf "$OUT/job" "$OUT/job_big"
timeout "$(lim 150)" python3 -m benchmarks.cuda_shards "$OUT/job" $OBJECTS --cpus $CPUS >"$OUT/shards.log" 2>&1
grep -E "^\{|^shards|^failure" "$OUT/shards.log" | cut -c1-400
step "3b. $BIG objects in one shard, $CPUS CPUs"
timeout "$(lim 180)" python3 -m benchmarks.cuda_shards "$OUT/job_big" $BIG --per-shard $BIG --cpus $CPUS >"$OUT/shards_big.log" 2>&1
grep -E "^\{|^shards|^failure" "$OUT/shards_big.log" | cut -c1-600
fi
if [[ $STEPS == *4* ]]; then
step "4. bench-synth ($DEVICE)"
timeout "$(lim 150)" python3 -m benchmarks.bench_synth --device $DEVICE $BENCH --out "$OUT/synth_$DEVICE.md" | tail -6
fi
if [[ $STEPS == *5* ]]; then
step "5. a whole job on real meshes ($REAL objects of manifests/real_dev.jsonl, $HAND, $CPUS CPUs)"
rm -rf "$OUT/job_real"
{ nvidia-smi --query-gpu=utilization.gpu,memory.used --format=csv,noheader,nounits -lms 500 >"$OUT/gpu_util.csv" 2>/dev/null & } ; SMI=$!
J0=$(date +%s.%N)
if python3 -c "import ray" 2>/dev/null; then
  # one shard of every object (one synthesis batch on the GPU), its CPUs as MuJoCo processes
  printf 'cpus_per_shard: %s\nobjects_per_shard: %s\n' "$CPUS" "$REAL" >"$OUT/job_real.yaml"
  timeout "$(lim 300)" python3 -m datagen.cli run --config "$OUT/job_real.yaml" --manifest manifests/real_dev.jsonl \
    --objects $REAL --hand $HAND --out "$OUT/job_real" --num-cpus $CPUS --no-progress >"$OUT/job_real.log" 2>&1
  python3 -m datagen.cli status "$OUT/job_real" --json >"$OUT/job_real_status.json" 2>>"$OUT/job_real.log"
  J1=$(date +%s.%N); python3 - "$OUT/job_real_status.json" "$J0" "$J1" <<'PY'
import json, sys
s = json.load(open(sys.argv[1])); wall = float(sys.argv[3]) - float(sys.argv[2])
print(f"ray job: wall_s={wall:.1f} shards_done={s['shards_done']}/{s['shards_total']} rows={s['grasps']} success={s['success']} "
      f"validated_per_gpu_hour={s['success'] / (wall / 3600):.0f} stages={s['stage_seconds']}")
PY
else
  echo "ray not importable: the same job's shards in-process (benchmarks/cuda_shards.py)"
  timeout "$(lim 300)" python3 -m benchmarks.cuda_shards "$OUT/job_real" $REAL --per-shard $REAL --cpus $CPUS \
    --manifest manifests/real_dev.jsonl --hand $HAND >"$OUT/job_real.log" 2>&1
  grep -E "^shards|^failure" "$OUT/job_real.log" | cut -c1-600
fi
kill $SMI 2>/dev/null
awk -F', *' 'NF>=2 {n++; s+=$1; if ($1>50) b++; if ($2>m) m=$2} END {if (n) printf "gpu utilisation: mean %.0f%%, samples > 50%%: %.0f%%, peak memory %d MiB (%d samples)\n", s/n, 100*b/n, m, n; else print "gpu utilisation: no nvidia-smi samples"}' "$OUT/gpu_util.csv"
fi
step done
