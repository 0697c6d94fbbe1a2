"""BODex's raw grasp files (before DexGraspBench's format step) into a grasp table.

One ``.npy`` dict per object and scene: ``robot_pose`` (1, N, 3, 7 + J) holds N grasps as
pregrasp, grasp, squeeze; each pose is [x y z qw qx qy qz] of the hand's palm link (its URDF
root, without the offsets DexGraspBench's XMLs put between their world frame and the palm) then
the joints in its URDF's order (Shadow: the thumb first). ``scene_path`` (a one-element list)
names a scene config (``np.save`` of a dict) whose ``task.obj_name`` object, under ``scene``, has
``file_path`` (relative to the scene file; the object folder is two levels up, laid out as
DexGraspBench's, `datagen.interop.objects`), ``scale`` (a list, first value used) and ``pose``
(7). A file with ``joint_names`` (BODex's own) has its joints mapped by name
(`BODEX_JOINT_NAMES`), otherwise they are taken in `BODEX_HANDS` order. BODex writes scene paths inside its tree (``.../src/curobo/content/...``); a path that does
not exist is looked up again under ``root`` from its ``src/curobo/content/`` part on.

Loading ``.npy`` dicts unpickles them: import only files you trust.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .dexgraspbench import PEER_HANDS as _DGB, grasp_columns
from .frames import PeerHand

__all__ = ["BODEX_HANDS", "BODEX_JOINT_NAMES", "read_bodex_files", "records"]

_CONTENT = "src/curobo/content/"
# our hand -> how BODex models it: its root is the URDF's root link, whose frame is the palm body's
# (DexGraspBench's BODex conversion, src/task/convert_format.py, puts its XML's world frame back
# by exactly the palm's pose in that XML: Shadow 0.034 m down z, Allegro quat (0 1 0 1), LEAP
# quat (0 1 0 0) and 0.1 m: `PEER_HANDS`); joints in its kinematics' order (Shadow: thumb first)
BODEX_HANDS: dict[str, PeerHand] = {
    "shadow_e3m5": PeerHand("shadow", "rh_palm", (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0),
                            _DGB["shadow_e3m5"].joints[17:] + _DGB["shadow_e3m5"].joints[:17]),
    "allegro": PeerHand("allegro", "palm", (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), _DGB["allegro"].joints),
    "leap": PeerHand("leap", "palm", (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), _DGB["leap"].joints),
}
# BODex's joint names (its URDFs': src/curobo/content/assets/robot/...) -> ours, for files that
# carry `joint_names` (BODex's save_helper writes them): such a file's joints are mapped by name,
# whatever their order. LEAP's URDF names j0..j15, j1 the index MCP (palm -> mcp_joint), j0 its
# rotation; Allegro's joint_0.0..joint_15.0 (index, middle, ring, thumb).
_LEAP_URDF = ("j1", "j0", "j2", "j3", "j5", "j4", "j6", "j7", "j9", "j8", "j10", "j11", "j12", "j13", "j14", "j15")
BODEX_JOINT_NAMES: dict[str, dict[str, str]] = {
    "shadow_e3m5": {j: j for j in BODEX_HANDS["shadow_e3m5"].joints},
    "allegro": {f"joint_{i}.0": j for i, j in enumerate(BODEX_HANDS["allegro"].joints)},
    "leap": dict(zip(_LEAP_URDF, BODEX_HANDS["leap"].joints)),
}


def _resolve(path: str, root: Path | None) -> Path:
    p = Path(path)
    if p.is_file():
        return p
    if _CONTENT in path and root is not None:
        q = Path(root) / path.split(_CONTENT, 1)[1]
        if q.is_file():
            return q
    raise FileNotFoundError(f"BODex scene config {path} not found"
                            + (f" (nor under {root})" if root else "; pass --root BODEX/src/curobo/content"))


def _by_name(pose: np.ndarray, names, hand: str | None, where: Path) -> np.ndarray:
    """(N, 3, 7 + J) poses with their joints put in `BODEX_HANDS` order, from the file's names."""
    names = [str(n) for n in np.asarray(names).reshape(-1)]
    table = BODEX_JOINT_NAMES.get(hand or "", {})
    want = BODEX_HANDS[hand].joints if hand in BODEX_HANDS else ()
    ours = [table.get(n, n) for n in names]
    missing = [j for j in want if j not in ours]
    if len(names) != pose.shape[-1] - 7 or missing:
        raise ValueError(f"{where}: joint_names {names} do not name the {len(want)} joints of BODex's {hand} hand "
                         f"(missing {missing}; its names: {sorted(table)})")
    return np.concatenate([pose[..., :7], pose[..., 7:][..., [ours.index(j) for j in want]]], axis=-1)


def records(paths: list[Path], root: Path | None = None, hand: str | None = None):
    """Yield one grasp record per BODex grasp (see `datagen.interop.dexgraspbench.records`);
    with ``hand`` (our name) a file's ``joint_names``, when it has them, order its joints."""
    for p in paths:
        d = np.load(p, allow_pickle=True).item()
        if "robot_pose" not in d or "scene_path" not in d:
            raise ValueError(f"{p}: not a BODex grasp file (no robot_pose/scene_path)")
        scene_file = _resolve(str(np.asarray(d["scene_path"]).reshape(-1)[0]), root)
        cfg = np.load(scene_file, allow_pickle=True).item()
        name = cfg["task"]["obj_name"]
        obj = cfg["scene"][name]
        folder = (scene_file.parent / obj["file_path"]).parent.parent
        pose = np.asarray(d["robot_pose"], dtype=np.float64)
        pose = pose.reshape(-1, *pose.shape[-2:])
        if pose.shape[-2] != 3:
            raise ValueError(f"{p}: robot_pose has {pose.shape[-2]} poses per grasp, expected 3 "
                             "(pregrasp, grasp, squeeze)")
        if "joint_names" in d and hand is not None:
            pose = _by_name(pose, d["joint_names"], hand, p)
        for i, poses in enumerate(pose):
            yield {"source": f"{p}#{i}", "obj_folder": folder, "obj_scale": float(np.ravel(obj["scale"])[0]),
                   "obj_pose": np.asarray(obj["pose"], dtype=np.float64), "poses": poses}


def read_bodex_files(paths: list[Path], hand, objects_dir: Path, root: Path | None = None) -> dict[str, list]:
    """Columns (see `datagen.interop.dexgraspbench.grasp_columns`) of BODex files ``paths``."""
    if hand.name not in BODEX_HANDS:
        raise ValueError(f"hand {hand.name!r}: BODex has no model of it; these hands convert: {sorted(BODEX_HANDS)}")
    return grasp_columns(records(paths, root, hand.name), hand, BODEX_HANDS[hand.name], objects_dir)
