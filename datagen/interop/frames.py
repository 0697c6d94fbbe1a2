"""Hand poses between this project's convention and a peer's (DexGraspBench, BODex).

A project pose is ``[x y z qw qx qy qz, joints in the hand MJCF's order]``: the root body's
pose (the hand spec's ``root_body``) and every joint. A peer pose roots the hand at another frame
(its hand XML's world frame) and lists fewer joints in its own order. Both describe the same
palm: this module converts through the palm link's pose, computed by the project's forward
kinematics (`datagen.hands.HandModel.link_poses`, itself checked against MuJoCo). Joints the peer
lacks (the Shadow E3M5's wrist, WRJ2 and WRJ1) fold into the peer's root on export and are 0 on
import.

Shapes: a pose (..., 7 + J) float64; transforms (..., 4, 4); metres and radians.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from scipy.spatial.transform import Rotation

__all__ = ["PeerHand", "from_peer", "matrix_to_pose7", "pose7_to_matrix", "to_peer"]


@dataclass(frozen=True)
class PeerHand:
    """How a peer models one of our hands: its palm body's pose in the peer's root frame, and its
    joint order (names as in our hand's MJCF)."""

    name: str                     #: the peer's hand name (its config/asset folder)
    palm: str                     #: palm body, the same name in both models
    palm_pos: tuple               #: (3,) metres: the palm body's position in the peer's root frame
    palm_quat: tuple              #: (4,) w x y z: its orientation there
    joints: tuple                 #: the peer's joint order

    def palm_in_root(self) -> np.ndarray:
        """(4, 4) transform of the palm body in the peer's root frame."""
        return pose7_to_matrix(np.array([*self.palm_pos, *self.palm_quat], dtype=np.float64))


def pose7_to_matrix(pose: np.ndarray) -> np.ndarray:
    """(..., 7) [x y z qw qx qy qz] -> (..., 4, 4); the quaternion need not be normalized."""
    pose = np.asarray(pose, dtype=np.float64)
    q = pose[..., 3:7] / np.linalg.norm(pose[..., 3:7], axis=-1, keepdims=True)
    T = np.zeros(pose.shape[:-1] + (4, 4))
    T[..., :3, :3] = Rotation.from_quat(q.reshape(-1, 4)[:, [1, 2, 3, 0]]).as_matrix().reshape(pose.shape[:-1] + (3, 3))
    T[..., :3, 3] = pose[..., :3]
    T[..., 3, 3] = 1.0
    return T


def matrix_to_pose7(T: np.ndarray) -> np.ndarray:
    """(..., 4, 4) -> (..., 7) [x y z qw qx qy qz] with qw >= 0."""
    T = np.asarray(T, dtype=np.float64)
    q = Rotation.from_matrix(T[..., :3, :3].reshape(-1, 3, 3)).as_quat()[:, [3, 0, 1, 2]]
    q = np.where(q[:, :1] < 0, -q, q).reshape(T.shape[:-2] + (4,))
    return np.concatenate([T[..., :3, 3], q], axis=-1)


def _palm_pose(hand, poses: np.ndarray, palm: str) -> np.ndarray:
    """(N, 4, 4) palm link transforms of project poses (N, 7 + J), in the hand's dtype (load it
    with ``dtype=torch.float64`` for exact conversions)."""
    p = torch.as_tensor(np.asarray(poses, dtype=np.float64), dtype=hand.dtype, device=hand.device)
    with torch.no_grad():
        T = hand.link_poses(p[:, :7], p[:, 7:])[palm]
    return T.cpu().numpy().astype(np.float64)


def _joint_map(hand, peer: PeerHand) -> np.ndarray:
    names = list(hand.joint_names)
    missing = [j for j in peer.joints if j not in names]
    if missing:
        raise ValueError(f"hand {hand.name!r} has no joints {missing} of the peer's {peer.name!r} hand")
    return np.array([names.index(j) for j in peer.joints])


def to_peer(hand, peer: PeerHand, poses: np.ndarray) -> np.ndarray:
    """Project poses (N, 7 + J) -> peer poses (N, 7 + len(peer.joints)): root = the pose of the
    peer's root frame that puts the palm where ours is."""
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 7 + hand.num_joints)
    root = _palm_pose(hand, poses, peer.palm) @ np.linalg.inv(peer.palm_in_root())
    return np.concatenate([matrix_to_pose7(root), poses[:, 7:][:, _joint_map(hand, peer)]], axis=1)


def from_peer(hand, peer: PeerHand, poses: np.ndarray) -> np.ndarray:
    """Peer poses (N, 7 + len(peer.joints)) -> project poses (N, 7 + J); joints the peer lacks
    are 0 (clamped into their limits)."""
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 7 + len(peer.joints))
    joints = np.zeros((len(poses), hand.num_joints))
    joints[:, _joint_map(hand, peer)] = poses[:, 7:]
    lo, hi = hand.joint_lower.cpu().numpy(), hand.joint_upper.cpu().numpy()
    lacking = np.setdiff1d(np.arange(hand.num_joints), _joint_map(hand, peer))
    joints[:, lacking] = np.clip(joints[:, lacking], lo[lacking], hi[lacking])
    palm = pose7_to_matrix(poses[:, :7]) @ peer.palm_in_root()
    identity = np.tile(np.array([0, 0, 0, 1.0, 0, 0, 0]), (len(poses), 1))
    palm_in_root = _palm_pose(hand, np.concatenate([identity, joints], axis=1), peer.palm)
    return np.concatenate([matrix_to_pose7(palm @ np.linalg.inv(palm_in_root)), joints], axis=1)
