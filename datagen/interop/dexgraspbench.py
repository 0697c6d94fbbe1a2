"""DexGraspBench's grasp files, out of a job and into a grasp table.

Its input is one ``.npy`` per grasp (``np.save`` of a dict, read with ``allow_pickle=True``)
under ``graspdata/<object>/scaleNNN_pose000/<i>.npy`` with ``obj_path`` (a peer object folder,
`datagen.interop.objects`), ``obj_scale``, ``obj_pose`` [x y z qw qx qy qz] (the object's world
pose) and ``pregrasp_qpos``, ``grasp_qpos``, ``squeeze_qpos``: 7 root values (the pose of its hand
XML's world frame) then the joints in its XML's order. `PEER_HANDS` holds, per hand this project
shares with it, where that XML puts the palm and the joint order (read from its public XMLs:
``assets/hand/{shadow,allegro}/right_hand.xml`` and, for LEAP, the MuJoCo Menagerie file its
``assets/hand/leap/right_hand.xml`` includes).

Export writes our grasps in the object's frame (``obj_pose`` identity) with the object's pieces
in normalized units (``obj_scale`` = ``object_scale_m``); a tabletop row (``scene`` tabletop) in
the table frame instead, for the peer's ``setting=tabletop`` (its floor at z = 0): ``obj_pose`` the
row's ``object_pose_table`` and the hand poses carried along with it, under
``scale<NNN>_pose<stable pose>``. Import reads such files back into rows
of the ``grasps`` schema plus processed objects, so ``datagen eval`` and ``datagen render`` take
them. Loading ``.npy`` dicts unpickles them: import only files you trust.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pyarrow as pa

from datagen._atomic import atomic_path

from datagen.hands.load import builtin_of

from .frames import PeerHand, from_peer, matrix_to_pose7, pose7_to_matrix, to_peer
from .objects import export_object, import_object

__all__ = ["PEER_HANDS", "export_grasps", "grasp_columns", "peer_hand", "read_grasp_files", "records"]

_SHADOW_JOINTS = tuple(f"rh_{f}J{j}" for f, n in (("FF", 4), ("MF", 4), ("RF", 4), ("LF", 5), ("TH", 5))
                       for j in range(n, 0, -1))
_S = math.sqrt(0.5)
# our hand name -> how DexGraspBench models it
PEER_HANDS: dict[str, PeerHand] = {
    "shadow_e3m5": PeerHand("shadow", "rh_palm", (0.0, 0.0, 0.034), (1.0, 0.0, 0.0, 0.0), _SHADOW_JOINTS),
    "allegro": PeerHand("allegro", "palm", (0.0, 0.0, 0.0), (0.0, _S, 0.0, _S),
                        tuple(f"{f}j{j}" for f in ("ff", "mf", "rf", "th") for j in range(4))),
    # Menagerie's leap_hand/right_hand.xml (which DexGraspBench includes) puts the palm 0.1 m up its
    # world z and turned 180 deg about x (the registry copy has it at the origin: datagen.hands.menagerie)
    "leap": PeerHand("leap", "palm", (0.0, 0.0, 0.1), (0.0, 1.0, 0.0, 0.0),
                     tuple(f"{f}_{j}" for f, js in (("if", ("mcp", "rot", "pip", "dip")),
                                                     ("mf", ("mcp", "rot", "pip", "dip")),
                                                     ("rf", ("mcp", "rot", "pip", "dip")),
                                                     ("th", ("cmc", "axl", "mcp", "ipl"))) for j in js)),
}
POSE_KEYS = ("pregrasp_qpos", "grasp_qpos", "squeeze_qpos")


def peer_hand(name: str) -> PeerHand:
    if name not in PEER_HANDS:
        raise ValueError(f"hand {name!r}: DexGraspBench has no model of it; these hands convert: "
                         f"{sorted(PEER_HANDS)}")
    return PEER_HANDS[name]


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "._-" else "_" for c in name)


def export_grasps(table: pa.Table, base: Path, out: Path, hand) -> list[Path]:
    """Write every row of ``table`` (grasps of ``hand``, a float64 `HandModel`) as DexGraspBench
    ``.npy`` files under ``out/graspdata`` and their objects under ``out/objects``. Relative
    ``object_path`` values are resolved against ``base``. Returns the written files."""
    peer = peer_hand(builtin_of(hand.spec) or hand.name)
    out = Path(out).resolve()
    scene = [c for c in ("scene", "stable_pose", "object_pose_table") if c in table.column_names]
    rows = table.select(["object_id", "object_scale_m", "object_path", "hand", "grasp_id", *POSE_KEYS, *scene]).to_pylist()
    if any(r["hand"] != hand.name for r in rows):
        raise ValueError(f"the table holds grasps of {sorted({r['hand'] for r in rows})}; export one hand at a time")
    folders: dict[str, Path] = {}
    counters: dict[tuple, int] = {}
    written = []
    for r in rows:
        entry = Path(r["object_path"])
        entry = entry if entry.is_absolute() else Path(base) / entry
        key = str(entry.resolve())
        if key not in folders:
            folders[key] = export_object(entry, out / "objects" / _safe(f"{r['object_id']}_{len(folders)}"))
        poses = to_peer(hand, peer, np.stack([np.asarray(r[k], dtype=np.float64) for k in POSE_KEYS]))
        obj_pose = np.array([0, 0, 0, 1, 0, 0, 0], dtype=np.float64)
        if r.get("scene") == "tabletop":  # the table frame: the peer's floor at z = 0 under the object
            obj_pose = np.asarray(r["object_pose_table"], dtype=np.float64)
            poses[:, :7] = matrix_to_pose7(pose7_to_matrix(obj_pose) @ pose7_to_matrix(poses[:, :7]))
        group = (r["object_id"], round(r["object_scale_m"] * 100), max(int(r.get("stable_pose", 0)), 0))
        i = counters.setdefault(group, 0)
        counters[group] = i + 1
        path = out / "graspdata" / _safe(r["object_id"]) / f"scale{group[1]:03d}_pose{group[2]:03d}" / f"{i}.npy"
        path.parent.mkdir(parents=True, exist_ok=True)
        data = {"obj_path": str(folders[key]), "obj_scale": float(r["object_scale_m"]),
                "obj_pose": obj_pose, "grasp_id": r["grasp_id"]}
        data.update({k: poses[j].astype(np.float32) for j, k in enumerate(POSE_KEYS)})
        with atomic_path(path) as tmp, open(tmp, "wb") as fh:  # a file object: np.save would add ".npy"
            np.save(fh, data, allow_pickle=True)
        written.append(path)
    return written


def records(paths: list[Path], root: Path | None = None):
    """Yield one grasp per DexGraspBench file: {source, obj_folder, obj_scale, obj_pose (7,),
    poses (3, 7 + joints)}. Relative ``obj_path`` values are resolved against ``root``
    (DexGraspBench's working directory; default: the current one)."""
    for p in paths:
        d = np.load(p, allow_pickle=True).item()
        missing = [k for k in ("obj_path", "obj_scale", "obj_pose", *POSE_KEYS) if k not in d]
        if missing:
            raise ValueError(f"{p}: not a DexGraspBench grasp file (no {missing})")
        folder = Path(str(d["obj_path"]))
        folder = folder if folder.is_absolute() else (Path(root) if root else Path.cwd()) / folder
        yield {"source": str(p), "obj_folder": folder, "obj_scale": float(d["obj_scale"]),
               "obj_pose": np.asarray(d["obj_pose"], dtype=np.float64),
               "poses": np.stack([np.asarray(d[k], dtype=np.float64) for k in POSE_KEYS])}


def read_grasp_files(paths: list[Path], hand, objects_dir: Path, root: Path | None = None) -> dict[str, list]:
    """Columns (see `grasp_columns`) of DexGraspBench grasp files ``paths`` of ``hand``."""
    return grasp_columns(records(paths, root), hand, peer_hand(hand.name), objects_dir)


def grasp_columns(recs, hand, peer: PeerHand, objects_dir: Path) -> dict[str, list]:
    """Columns (object_id, object_scale_m, object_path, source, the three poses) of peer grasp
    records (see `records`) of ``hand`` (a float64 `HandModel`), posed in our object frame; their
    objects become processed entries under ``objects_dir``, named by ``object_path`` relative to
    ``objects_dir.parent``."""
    objects: dict[str, tuple] = {}
    cols: dict[str, list] = {k: [] for k in ("object_id", "object_scale_m", "object_path", "source", *POSE_KEYS)}
    for r in recs:
        folder = Path(r["obj_folder"])
        key = str(folder.resolve())
        if key not in objects:
            oid = folder.name
            entry = objects_dir / _safe(f"{oid}_{len(objects)}")
            centre, factor = import_object(folder, oid, entry)
            objects[key] = (oid, centre, factor, entry.relative_to(objects_dir.parent).as_posix())
        oid, centre, factor, rel = objects[key]
        scale = r["obj_scale"]
        # peer world -> object frame (peer mesh units x scale) -> ours (bounding-box centre at the origin)
        to_obj = np.linalg.inv(pose7_to_matrix(r["obj_pose"]))
        to_obj[:3, 3] -= centre * scale
        ours = from_peer(hand, peer, r["poses"])
        ours[:, :7] = matrix_to_pose7(to_obj @ pose7_to_matrix(ours[:, :7]))
        cols["object_id"].append(oid)
        cols["object_scale_m"].append(scale / factor)
        cols["object_path"].append(rel)
        cols["source"].append(r["source"])
        for j, k in enumerate(POSE_KEYS):
            cols[k].append(ours[j])
    return cols
