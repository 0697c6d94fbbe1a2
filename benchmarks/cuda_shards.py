"""The default job's shards run in this process, without Ray, on CUDA when there is a GPU.

Part of the GPU check (`benchmarks/cuda_check.sh`): it runs `workers.shard.run_shard` exactly
as a Ray task would (processing, synthesis, MuJoCo evaluation, Parquet), one shard after the
other, then prints each shard's summary, the per-stage totals and the failures. Ray itself is
not needed, so the check also runs where Ray cannot be installed. Usage:
``python -m benchmarks.cuda_shards OUT_DIR [OBJECTS] [--cpus N] [--per-shard P] [--manifest M]
[--hand H]`` (default 6 procedural objects, the `make dataset` job, one CPU per shard, 2 objects per shard). A GPU wants
larger synthesis batches: ``--per-shard 16`` puts 16 objects (32 targets) in one shard's batch.
"""

from __future__ import annotations

import argparse
import json
import time

import pyarrow.parquet as pq
import torch

from workers.job import PREFERRED_PER_SHARD, JobConfig, JobDir, shard_slices
from workers.finished import merge_failures
from workers.setup import prepare_manifest
from workers.shard import run_shard


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", help="job directory (created)")
    ap.add_argument("objects", type=int, nargs="?", default=6)
    ap.add_argument("--cpus", type=float, default=1.0, help="cpus_per_shard: torch threads and evaluation processes")
    ap.add_argument("--per-shard", type=int, default=PREFERRED_PER_SHARD, help="objects_per_shard")
    ap.add_argument("--manifest", default="", help="a manifest's first OBJECTS objects (e.g. manifests/real_dev.jsonl: "
                    "real meshes) instead of procedural ones")
    ap.add_argument("--hand", default="shadow")
    args = ap.parse_args()
    cfg = JobConfig(count=args.objects, cpus_per_shard=args.cpus, objects_per_shard=args.per_shard,
                    manifest=args.manifest, hand=args.hand)
    job = JobDir(args.out)
    job.init(cfg)
    entries = prepare_manifest(job, cfg)
    doc = job.read_job()
    prov = {"code_version": doc["code_version"], "packages": doc["packages"], "created_at": doc["created_at"],
            "cache": ""}
    t0 = time.perf_counter()
    sums = []
    for i, (a, b) in enumerate(shard_slices(len(entries), cfg.objects_per_shard)):
        ents = [{**e.__dict__, "scales": list(e.scales)} for e in entries[a:b]]
        sums.append(run_shard(str(job.path), i, ents, cfg.to_dict(), prov))
        print(json.dumps(sums[-1]), flush=True)
    merge_failures(job)
    wall = time.perf_counter() - t0
    stages = {k: round(sum(s["timings"][k] for s in sums), 1) for k in sums[0]["timings"]}
    gpu = torch.cuda.get_device_name(0) if torch.cuda.is_available() else "no GPU"
    ok = sum(s["success"] for s in sums)
    print(f"shards: device={sums[0]['device']} ({gpu}) hand={args.hand} objects={args.objects} "
          f"source={args.manifest or 'procedural'} per_shard={args.per_shard} cpus={args.cpus} "
          f"rows={sum(s['grasps'] for s in sums)} success={ok} wall_s={wall:.1f} "
          f"validated_per_gpu_hour={ok / (wall / 3600):.0f} stages={stages}")
    for f in pq.read_table(job.failures_path).to_pylist():
        print("failure:", f["object_id"], f["stage"], f["reason"], " ".join(str(f["message"]).split())[:300])


if __name__ == "__main__":  # the objects' isolated processing spawns interpreters that import this module
    main()
