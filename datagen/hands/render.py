"""A picture of a hand's collision spheres, fingertip contact points and palm frame, for review.

Offscreen MuJoCo rendering; on a machine without a display run with ``MUJOCO_GL=osmesa``
(``apt-get install -y libosmesa6``, PyOpenGL) or ``MUJOCO_GL=egl``. The variable is read when
mujoco is first imported, so set it in the environment, not from Python.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import mujoco
import numpy as np

from datagen._atomic import atomic_write_bytes

from .mjcf import FlatHand
from .spec import HandSpec, HandSpecError

__all__ = ["render_spec", "render_spec_file", "write_png"]


def write_png(path: str | Path, image: np.ndarray) -> None:
    """Write an (H, W, 3) uint8 RGB image as PNG (no imaging dependency)."""
    h, w, _ = image.shape
    raw = b"".join(b"\x00" + image[row].astype(np.uint8).tobytes() for row in range(h))

    def chunk(tag: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    png = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
           + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b""))
    atomic_write_bytes(path, png)


def _annotated_model(spec: HandSpec, flat: FlatHand) -> mujoco.MjModel:
    ms = mujoco.MjSpec.from_string(flat.xml)
    for g in ms.geoms:  # hide MuJoCo's own collision geoms; keep the visual meshes
        if g.contype or g.conaffinity:
            g.group = 5
    for link, spheres in spec.spheres.items():
        body = ms.body(link)
        for x, y, z, r in spheres:
            body.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[r, 0, 0], pos=[x, y, z], contype=0,
                          conaffinity=0, group=0, rgba=[0.2, 0.6, 1.0, 0.35])
    for tip in spec.fingertips.values():
        body = ms.body(tip.link)
        p, n = np.asarray(tip.point), np.asarray(tip.normal)
        body.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.003, 0, 0], pos=p.tolist(), contype=0,
                      conaffinity=0, group=0, rgba=[1, 0.1, 0.1, 1])
        body.add_geom(type=mujoco.mjtGeom.mjGEOM_CAPSULE, size=[0.0008, 0, 0], fromto=[*p, *(p + 0.015 * n)],
                      contype=0, conaffinity=0, group=0, rgba=[1, 0.5, 0, 1])
    palm = ms.body(spec.palm.link)
    o = np.asarray(spec.palm.origin)
    for axis, rgba in ((spec.palm.approach, [0.1, 0.1, 1, 1]), (spec.palm.thumb, [0.1, 0.8, 0.1, 1])):
        palm.add_geom(type=mujoco.mjtGeom.mjGEOM_CAPSULE, size=[0.0015, 0, 0],
                      fromto=[*o, *(o + 0.05 * np.asarray(axis))], contype=0, conaffinity=0, group=0, rgba=rgba)
    ms.worldbody.add_light(pos=[0, 0, 2], dir=[0, 0, -1], type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL,
                           castshadow=0)
    return ms.compile()


def render_spec(spec: HandSpec, flat: FlatHand, path: str | Path, *, width: int = 640, height: int = 480) -> None:
    """Render the open pose from the palm side and from the thumb side, side by side, to ``path``
    (PNG): blue spheres, red contact points with orange pad normals, palm approach (blue) and
    thumb (green) axes."""
    model = _annotated_model(spec, flat)
    data = mujoco.MjData(model)
    for name, value in spec.open_pose.items():
        data.qpos[model.jnt_qposadr[model.joint(name).id]] = value
    mujoco.mj_forward(model, data)
    pb = model.body(spec.palm.link).id
    R = data.xmat[pb].reshape(3, 3)
    views = [-(R @ np.asarray(spec.palm.approach)), -(R @ np.asarray(spec.palm.thumb))]
    origin = data.xpos[pb] + R @ np.asarray(spec.palm.origin)
    tips = [data.xpos[model.body(t.link).id] + data.xmat[model.body(t.link).id].reshape(3, 3) @ np.asarray(t.point)
            for t in spec.fingertips.values()]
    lookat = (origin + np.mean(tips, axis=0)) / 2
    distance = 2.5 * max(np.linalg.norm(np.asarray(tips) - lookat, axis=1).max(), 0.05) + 0.05
    try:
        renderer = mujoco.Renderer(model, height=height, width=width)
    except Exception as exc:
        raise HandSpecError(path, f"cannot open an offscreen GL context: {exc}",
                            "set MUJOCO_GL=osmesa (apt-get install -y libosmesa6) or MUJOCO_GL=egl") from None
    try:
        option = mujoco.MjvOption()
        option.geomgroup[:] = [1, 1, 1, 0, 0, 0]
        frames = []
        for forward in views:
            cam = mujoco.MjvCamera()
            cam.lookat[:] = lookat
            cam.distance = distance
            cam.azimuth = float(np.degrees(np.arctan2(forward[1], forward[0])))
            cam.elevation = float(np.degrees(np.arcsin(np.clip(forward[2], -1, 1))))
            renderer.update_scene(data, camera=cam, scene_option=option)
            frames.append(renderer.render().copy())
    finally:
        renderer.close()
    write_png(path, np.concatenate(frames, axis=1))


def render_spec_file(spec_path: str, png: str) -> None:
    """`render_spec` of the spec file at ``spec_path`` (a process pool's entry point: plain arguments)."""
    from .load import load_hand

    hand = load_hand(spec_path)
    flat = FlatHand(xml=hand.mjcf_path.read_text(), model=hand.mj_model, path=hand.mjcf_path, source=hand.mjcf_path)
    render_spec(hand.spec, flat, png)
