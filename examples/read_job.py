"""Read a finished (or running) dataset job into a torch DataLoader.

    make dataset SCALE=6 OUT=jobs/default            # build a job (Ray, local cores)
    python examples/read_job.py jobs/default         # then read it

`datagen.GraspDataset` loads the job's finished shards (schema-checked) into memory; each item
is a dict of pose tensors ``(nq,)`` = [x y z qw qx qy qz] metres + joints (radians, object
frame), the object's scale and id, and the MuJoCo verdict.
"""

from __future__ import annotations

import argparse

import torch
from torch.utils.data import DataLoader

import datagen


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("job", help="a job directory (datagen run --out JOB)")
    ap.add_argument("--all", action="store_true", help="also the grasps that failed the MuJoCo tests")
    ap.add_argument("--batch-size", type=int, default=256)
    args = ap.parse_args()

    table = datagen.read_job(args.job, columns=["object_id", "task", "success"])
    print(f"{args.job}: {table.num_rows} grasps, {sum(table['success'].to_pylist())} successful, "
          f"{len(set(table['object_id'].to_pylist()))} objects, tasks {sorted(set(table['task'].to_pylist()))}")

    data = datagen.GraspDataset(args.job, only_success=not args.all)
    if len(data) == 0:
        raise SystemExit("no grasps to load (use --all to include the failed ones)")
    loader = DataLoader(data, batch_size=args.batch_size, shuffle=True, generator=torch.Generator().manual_seed(0))
    print(f"{len(data)} items, {len(data.joint_names)} joints ({', '.join(data.joint_names[:4])}, ...)")
    for batch in loader:
        grasp = batch["grasp_qpos"]  # (batch, 7 + J)
        print(f"batch: grasp_qpos {tuple(grasp.shape)} {grasp.dtype}, scales {batch['object_scale'][:4].tolist()}, "
              f"first object {batch['object_id'][0]}; root quaternion norms "
              f"{grasp[:, 3:7].norm(dim=-1).min():.4f}..{grasp[:, 3:7].norm(dim=-1).max():.4f}")
        break


if __name__ == "__main__":
    main()
