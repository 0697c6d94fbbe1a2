"""`HandModel`: batched, differentiable kinematics of one hand plus what grasp synthesis needs.

Notation (shapes): ``...`` any batch shape, J joints, L links, S collision spheres, F fingertips,
P self-collision sphere pairs, nu actuators. Units: metres, radians.

Row format (the dataset's): a hand configuration is ``root_pose (..., 7)`` = [x y z qw qx qy qz],
the world pose of the root body (position, unit quaternion; normalized here, so gradients may
flow through an unnormalized quaternion), followed by ``joints (..., J)`` in the flattened hand
MJCF's joint order (``joint_names``). In MuJoCo the same hand is ``mjcf_path``; its qpos is
``joints_to_qpos(joints)`` and its position-actuator controls ``joints_to_ctrl(joints)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np
import torch

from datagen.rotation import quat_to_matrix as quaternion_to_matrix
from datagen.scatter import index_rows

from .mjcf import FlatHand, actuator_matrix, build_chain
from .spec import HandSpec, HandSpecError

__all__ = ["HandModel", "quaternion_to_matrix"]


@dataclass(frozen=True)
class PalmPose:
    """World palm frame: origin (..., 3) m, approach (..., 3) and thumb (..., 3) unit axes."""

    origin: torch.Tensor
    approach: torch.Tensor
    thumb: torch.Tensor


class HandModel:
    """A hand loaded from a `HandSpec` (use `datagen.hands.load_hand`). See the module docstring."""

    def __init__(self, spec: HandSpec, flat: FlatHand, *, device=None, dtype=None) -> None:
        self.spec = spec
        self.name = spec.name
        self.mjcf_path: Path = flat.path
        self.mj_model: mujoco.MjModel = flat.model
        self.device = torch.device(device or "cpu")
        self.dtype = dtype or torch.float32
        m, where = flat.model, spec.source_file
        self.joint_names: list[str] = [m.joint(j).name for j in range(m.njnt)]
        self.link_names: list[str] = [m.body(b).name for b in range(1, m.nbody)]
        if any(not n for n in self.link_names + self.joint_names) or len(set(self.link_names)) != len(self.link_names):
            raise HandSpecError(where, "every hand body and joint needs a unique name", "name them in the MJCF")
        need_link = _lookup(self.link_names, "link", where)
        need_joint = _lookup(self.joint_names, "joint", where)
        self._build_chain(flat, where)
        lo, hi = _joint_limits(m)
        self._np = {"lower": lo, "upper": hi}
        sph_arr, sph_link, first = _sphere_table(spec, need_link)
        tips = list(spec.fingertips.values())
        self.fingertip_names: list[str] = list(spec.fingertips)
        self.palm_link = need_link(spec.palm.link, "palm")
        self.sphere_margin_m: float = spec.sphere_margin_m
        self._couple = [(need_joint(c.joint, "couplings"), need_joint(c.leader, "couplings"), c.ratio, c.offset)
                        for c in spec.couplings]
        open_pose = np.clip(np.zeros(m.njnt), lo, hi)
        for name, value in spec.open_pose.items():
            open_pose[need_joint(name, "open_pose")] = value
        # each fingertip's contact sphere (index into the spheres) where the spec names one, else None
        self.fingertip_spheres: list[int | None] = [
            None if t.sphere is None else first[need_link(t.link, "fingertips")] + t.sphere for t in tips]
        self.self_collision_link_pairs: list[tuple[str, str]] = [(p.link_a, p.link_b)
                                                                  for p in spec.self_collision_pairs]
        self.actuator_names: list[str] = [m.actuator(u).name for u in range(m.nu)]
        self._host = {
            "joint_lower": lo, "joint_upper": hi,
            "sphere_centres_local": sph_arr[:, :3], "sphere_radii": sph_arr[:, 3],
            "fingertip_points_local": np.array([t.point for t in tips]),
            "fingertip_normals_local": np.array([t.normal for t in tips]),
            "palm_local": np.array([spec.palm.origin, spec.palm.approach, spec.palm.thumb]),
            "ctrl_matrix": actuator_matrix(m, flat.source), "ctrl_range": m.actuator_ctrlrange.copy(),
        }
        self._index = {
            "sphere_link": np.asarray(sph_link, dtype=np.int64),
            "fingertip_link": np.asarray([need_link(t.link, "fingertips") for t in tips], dtype=np.int64),
            "self_collision_pairs": _sphere_pairs(spec, sph_link, first, need_link),
            "qpos_index": m.jnt_qposadr.astype(np.int64),
        }
        self._open_pose = open_pose
        self._move()
        self.open_pose = self.apply_couplings(self.open_pose)
        self._check_against_mujoco(where)

    def _build_chain(self, flat: FlatHand, where: str | None) -> None:
        """The pytorch-kinematics chain of the flattened MJCF, its joint order mapped to ours."""
        self.chain = build_chain(flat.xml, flat.model.body(1).name, dtype=self.dtype, device=self.device)
        chain_joints = self.chain.get_joint_parameter_names()
        if sorted(chain_joints) != sorted(self.joint_names):
            raise HandSpecError(where, "pytorch-kinematics and MuJoCo disagree on the joints")
        joint_index = {n: i for i, n in enumerate(self.joint_names)}
        self._chain_perm = [joint_index[n] for n in chain_joints]  # chain order -> our order
        self._frame_idx = self.chain.get_frame_indices(*self.link_names)

    def _check_against_mujoco(self, where: str | None, tol: float = 1e-4) -> None:
        """One FK evaluation against mj_kinematics at load: catches what pytorch-kinematics'
        MJCF import cannot express (e.g. a joint with a non-zero ``pos``) before it goes unnoticed."""
        m = self.mj_model
        lo, hi = self._np["lower"], self._np["upper"]
        q = lo + (0.3 + 0.4 * (np.arange(m.njnt) % 3) / 2) * (hi - lo)  # a spread, in-range configuration
        data = mujoco.MjData(m)
        data.qpos[:] = self.joints_to_qpos(q)
        mujoco.mj_kinematics(m, data)
        root = torch.tensor([0, 0, 0, 1, 0, 0, 0], dtype=self.dtype, device=self.device)
        T = self.link_transforms(root, torch.as_tensor(q, dtype=self.dtype, device=self.device))
        T = T.detach().cpu().double().numpy()
        err = max(np.abs(T[:, :3, 3] - data.xpos[1:]).max(), np.abs(T[:, :3, :3] - data.xmat[1:].reshape(-1, 3, 3)).max())
        if err > tol:
            raise HandSpecError(where, f"pytorch-kinematics FK disagrees with MuJoCo by {err:.2e}",
                                "unsupported MJCF kinematics (e.g. a joint with a non-zero pos)")

    # ------------------------------------------------------------------ device handling
    def _move(self) -> None:
        for k, v in self._host.items():
            setattr(self, k, torch.as_tensor(v, dtype=self.dtype, device=self.device))
        names = {"sphere_link": "sphere_link_index", "fingertip_link": "fingertip_link_index",
                 "self_collision_pairs": "self_collision_pairs", "qpos_index": "qpos_index"}
        for k, v in self._index.items():
            setattr(self, names[k], torch.as_tensor(v, device=self.device))
        self.open_pose = torch.as_tensor(self._open_pose, dtype=self.dtype, device=self.device)

    def to(self, device=None, dtype=None) -> "HandModel":
        """Move every tensor (and the chain) to ``device`` / ``dtype``; returns self."""
        self.device = torch.device(device) if device is not None else self.device
        self.dtype = dtype or self.dtype
        self.chain = self.chain.to(dtype=self.dtype, device=self.device)
        self._move()
        self.open_pose = self.apply_couplings(self.open_pose)
        return self

    # ------------------------------------------------------------------ sizes
    @property
    def num_joints(self) -> int:
        return len(self.joint_names)

    @property
    def num_spheres(self) -> int:
        return int(self.sphere_radii.shape[0])

    # ------------------------------------------------------------------ joints
    def clamp_joints(self, joints: torch.Tensor) -> torch.Tensor:
        """(..., J) joints clipped to the joint limits."""
        return torch.maximum(torch.minimum(joints, self.joint_upper), self.joint_lower)

    def apply_couplings(self, joints: torch.Tensor) -> torch.Tensor:
        """(..., J) joints within limits with each coupled joint on its coupling: the follower is set
        to ratio * leader + offset and, where that leaves its range, the leader is moved back so
        the pair stays coupled. Shadow: distal J0 = 1.142 * middle J1, as its tendon enforces."""
        if not self._couple:
            return self.clamp_joints(joints)
        out = self.clamp_joints(joints).clone()
        lo, hi = self.joint_lower, self.joint_upper
        for follower, leader, ratio, offset in self._couple:
            f = (ratio * out[..., leader] + offset).clamp(lo[follower], hi[follower])
            out[..., follower] = f
            if ratio != 0:  # where the follower hit its limit, pull the leader back onto the coupling
                out[..., leader] = ((f - offset) / ratio).clamp(lo[leader], hi[leader])
        return out

    def random_joints(self, shape: tuple[int, ...], generator: torch.Generator | None = None) -> torch.Tensor:
        """(*shape, J) uniform joints within limits (couplings not applied)."""
        u = torch.rand(shape + (self.num_joints,), generator=generator, dtype=self.dtype).to(self.device)
        return self.joint_lower + u * (self.joint_upper - self.joint_lower)

    def joints_to_qpos(self, joints: torch.Tensor | np.ndarray) -> np.ndarray:
        """(..., nq) MuJoCo qpos of ``mjcf_path``'s model (float64 numpy) for joints (..., J)."""
        q = np.asarray(joints.detach().cpu() if isinstance(joints, torch.Tensor) else joints, dtype=np.float64)
        out = np.zeros(q.shape[:-1] + (self.mj_model.nq,))
        out[..., self._index["qpos_index"]] = q
        return out

    def joints_to_ctrl(self, joints: torch.Tensor) -> torch.Tensor:
        """(..., nu) position-actuator targets for joints (..., J), clipped to ctrlrange. Tendon
        actuators (Shadow E3M5's J1+J2) get the tendon length their joints imply."""
        ctrl = joints @ self.ctrl_matrix.T
        return torch.maximum(torch.minimum(ctrl, self.ctrl_range[:, 1]), self.ctrl_range[:, 0])

    # ------------------------------------------------------------------ kinematics
    def link_transforms(self, root_pose: torch.Tensor, joints: torch.Tensor) -> torch.Tensor:
        """(..., L, 4, 4) world transforms of all links for root_pose (..., 7) and joints (..., J)."""
        # numpy's rule, not torch.broadcast_shapes: torch's imports sympy on first use (0.4 s per process)
        batch = torch.Size(np.broadcast_shapes(root_pose.shape[:-1], joints.shape[:-1]))
        th = joints.expand(batch + joints.shape[-1:]).reshape(-1, joints.shape[-1])[:, self._chain_perm]
        frames = self.chain.forward_kinematics_tensor(th)  # (frames, B, 4, 4), root frame
        local = frames[self._frame_idx].transpose(0, 1)  # (B, L, 4, 4)
        root = root_pose.expand(batch + (7,)).reshape(-1, 7)
        R = quaternion_to_matrix(root[:, 3:])  # (B, 3, 3)
        rot = R[:, None] @ local[..., :3, :3]
        pos = (R[:, None] @ local[..., :3, 3:]).squeeze(-1) + root[:, None, :3]
        bottom = local[..., 3:, :]
        T = torch.cat([torch.cat([rot, pos[..., None]], dim=-1), bottom], dim=-2)
        return T.reshape(batch + T.shape[1:])

    def link_poses(self, root_pose: torch.Tensor, joints: torch.Tensor) -> dict[str, torch.Tensor]:
        """{link name: (..., 4, 4) world transform} (see `link_transforms`)."""
        T = self.link_transforms(root_pose, joints)
        return {name: T[..., i, :, :] for i, name in enumerate(self.link_names)}

    @staticmethod
    def _apply(T: torch.Tensor, index: torch.Tensor, local: torch.Tensor, direction: bool = False) -> torch.Tensor:
        # R @ p + t written out column by column, in a links-first layout: each column of the links'
        # 3 x 4 blocks, (..., L, 4, 4) -> (L, B x 3), is gathered per point along dim 0, (N, B, 3), so
        # that its gradient scatters back as whole contiguous rows (index_add_ along a later dim
        # loops over strided slices: 5 ms per column at 1600 Shadow poses); each column is then
        # scaled by the point's coordinate. The columns are split at link size (their gradients are
        # stacked there, not at point size: 8 ms per evaluation at 800 Shadow poses). The same
        # arithmetic as the batched 3 x 3 @ 3 x 1 matmul (identical values), without one tiny GEMM
        # per point and pose. On CUDA the rows are read by `index_rows`, whose gradient sums in a
        # fixed order (index_select's would add atomically: poses that differ from run to run).
        batch, L = T.shape[:-3], T.shape[-3]
        cols = T[..., :3, :].reshape(-1, L, 3, 4).permute(3, 1, 0, 2).reshape(4, L, -1)  # (4, L, B 3)
        used = cols[:3] if direction else cols  # a direction skips the translation column
        c = [index_rows(col, index).view(len(index), -1, 3) for col in used.unbind(0)]  # (N, B, 3) each
        p = local.t()[:, :, None, None]  # (3, N, 1, 1)
        out = c[0] * p[0] + c[1] * p[1] + c[2] * p[2]  # (N, B, 3)
        if not direction:
            out = out + c[3]
        return out.transpose(0, 1).reshape(batch + (len(index), 3))

    def spheres(self, root_pose: torch.Tensor, joints: torch.Tensor,
                transforms: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """World collision spheres: centres (..., S, 3) m and radii (S,) m. ``transforms`` (from
        `link_transforms`) skips the FK when the caller already has it."""
        T = self.link_transforms(root_pose, joints) if transforms is None else transforms
        return self._apply(T, self.sphere_link_index, self.sphere_centres_local), self.sphere_radii

    def fingertip_points(self, root_pose: torch.Tensor, joints: torch.Tensor,
                         transforms: torch.Tensor | None = None) -> torch.Tensor:
        """(..., F, 3) world fingertip contact points (m), in ``fingertip_names`` order."""
        T = self.link_transforms(root_pose, joints) if transforms is None else transforms
        return self._apply(T, self.fingertip_link_index, self.fingertip_points_local)

    def fingertip_normals(self, root_pose: torch.Tensor, joints: torch.Tensor,
                          transforms: torch.Tensor | None = None) -> torch.Tensor:
        """(..., F, 3) world outward pad normals (unit) at the fingertip contact points."""
        T = self.link_transforms(root_pose, joints) if transforms is None else transforms
        return self._apply(T, self.fingertip_link_index, self.fingertip_normals_local, direction=True)

    def palm_frame(self, root_pose: torch.Tensor, joints: torch.Tensor,
                   transforms: torch.Tensor | None = None) -> PalmPose:
        """World palm frame (origin, approach = palm normal out of the palm, thumb axis)."""
        T = self.link_transforms(root_pose, joints) if transforms is None else transforms
        Tp = T[..., self.palm_link, :, :]
        R, t = Tp[..., :3, :3], Tp[..., :3, 3]
        o, a, th = self.palm_local
        return PalmPose(origin=(R @ o) + t, approach=R @ a, thumb=R @ th)

    def self_penetration(self, root_pose: torch.Tensor, joints: torch.Tensor,
                         transforms: torch.Tensor | None = None) -> torch.Tensor:
        """(..., P) overlap depth (m, >= 0) of each self-collision sphere pair."""
        c, r = self.spheres(root_pose, joints, transforms)
        i, j = self.self_collision_pairs[:, 0], self.self_collision_pairs[:, 1]
        d = (c[..., i, :] - c[..., j, :]).norm(dim=-1)
        return torch.relu(r[i] + r[j] - d)

    def __repr__(self) -> str:
        return (f"HandModel({self.name!r}, joints={self.num_joints}, links={len(self.link_names)}, "
                f"spheres={self.num_spheres}, fingertips={self.fingertip_names}, device={self.device}, "
                f"dtype={self.dtype})")


def _lookup(names: list[str], kind: str, where: str | None):
    """``need(name, what) -> index`` into ``names``; an unknown name raises naming the spec field."""
    index = {n: i for i, n in enumerate(names)}

    def need(name: str, what: str) -> int:
        if name not in index:
            raise HandSpecError(where, f"{what} names unknown {kind} {name!r}", f"{kind}s: {names}")
        return index[name]
    return need


def _joint_limits(m: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper limits (J,), rad or m; an unlimited joint gets [-pi, pi]."""
    limited = m.jnt_limited.astype(bool)
    return np.where(limited, m.jnt_range[:, 0], -np.pi), np.where(limited, m.jnt_range[:, 1], np.pi)


def _sphere_table(spec: HandSpec, need_link) -> tuple[np.ndarray, list[int], dict[int, int]]:
    """The spec's spheres as ``(S, 4)`` [x y z r] in their links' frames (m), each sphere's link
    index, and each link's first sphere index."""
    sph, sph_link = [], []
    for link, spheres in spec.spheres.items():
        i = need_link(link, "spheres")
        sph += list(spheres)
        sph_link += [i] * len(spheres)
    first: dict[int, int] = {}
    for k, li in enumerate(sph_link):
        first.setdefault(li, k)
    return np.asarray(sph, dtype=np.float64).reshape(-1, 4), sph_link, first


def _sphere_pairs(spec: HandSpec, sph_link: list[int], first: dict[int, int], need_link) -> np.ndarray:
    """``(P, 2)`` sphere index pairs of the spec's self-collision link pairs (empty lists = all)."""
    pairs = []
    for pr in spec.self_collision_pairs:
        ia, ib = need_link(pr.link_a, "self_collision_pairs"), need_link(pr.link_b, "self_collision_pairs")
        na, nb = sph_link.count(ia), sph_link.count(ib)
        sa = [first[ia] + i for i in (pr.spheres_a or range(na))]
        sb = [first[ib] + i for i in (pr.spheres_b or range(nb))]
        pairs += [(x, y) for x in sa for y in sb]
    return np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
