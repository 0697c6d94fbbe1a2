"""Imported grasps as rows of the ``grasps`` schema (synthesis-only columns left null)."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pyarrow as pa

import datagen
from datagen.synth.rows import hand_asset_sha256
from schemas import arrow_schema

__all__ = ["imported_table"]


def imported_table(cols: dict[str, list], hand, fmt: str, task: str = "force_closure") -> pa.Table:
    """A ``grasps`` table of imported poses: ``cols`` holds object_id, object_scale_m, object_path,
    source (the file each grasp came from) and the three pose columns ((7 + J,) arrays). Energies,
    contacts, seeds and init_qpos are null (the peer does not record them); task ``task`` with
    w_t = +z torque and gamma 180 deg (force closure)."""
    n = len(cols["object_id"])
    nq = 7 + hand.num_joints
    schema = arrow_schema("grasps", nq=nq)
    index: dict[tuple, int] = {}
    gi = []
    for oid, s in zip(cols["object_id"], cols["object_scale_m"]):
        gi.append(index.get((oid, s), 0))
        index[(oid, s)] = gi[-1] + 1
    values = {
        "grasp_id": [hashlib.sha256(f"{fmt}|{src}|{i}".encode()).hexdigest()[:24]
                     for i, src in enumerate(cols["source"])],
        "object_id": cols["object_id"], "split": [""] * n, "object_scale_m": cols["object_scale_m"],
        "object_path": cols["object_path"], "mesh_sha256": [""] * n, "hand": [hand.name] * n,
        "hand_asset_sha256": [hand_asset_sha256(hand)] * n, "joint_names": [list(hand.joint_names)] * n,
        "task": [task] * n, "w_t": [[0, 0, 0, 0, 0, 1.0]] * n, "gamma_deg": [180.0] * n,
        "grasp_index": gi,
    }
    for k in ("pregrasp_qpos", "grasp_qpos", "squeeze_qpos"):
        values[k] = [np.asarray(q, dtype=np.float32).tolist() for q in cols[k]]
    arrays = [pa.array(values[f.name], type=f.type) if f.name in values else pa.nulls(n, type=f.type)
              for f in schema]
    meta = dict(schema.metadata)
    meta.update({b"datagen.joint_names": json.dumps(hand.joint_names).encode(),
                 b"datagen.code_version": datagen.__version__.encode(),
                 b"datagen.imported_from": fmt.encode()})
    return pa.Table.from_arrays(arrays, schema=schema.with_metadata(meta))
