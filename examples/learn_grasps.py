"""A reference learner: a conditional VAE of grasps given the object's point cloud, trained on
jobs' train splits, its samples on the test splits' objects put through the same MuJoCo test.

    python examples/learn_grasps.py JOB_DIR [JOB_DIR ...] --out learn/   # or: make learn

What it does, in plain torch beside `datagen.io` and the hand's kinematics (`datagen.hands`):

1. data: `datagen.io.ObservationGraspDataset` pairs each successful train grasp with its object's
   observation at its scale (``--input surface``: ``--points`` surface points with normals;
   ``--input view``: one single-view depth cloud of ``--points`` points, a random view per step);
2. grasp vector, in the object's frame: the root rotation as its matrix's first two columns (6D),
   the object's centre in the hand's root frame (``-R^T t``, centimetres, nearly constant across
   grasps: the object sits in front of the palm), joints mapped to [-1, 1] by the hand's limits,
   pregrasp and squeeze joint offsets;
3. model: a PointNet encoder (shared per-point MLP of the point and its offset from the cloud's
   centroid, max-pool) conditions a CVAE; its loss is the vector's squared error (each unit about
   1 cm of hand motion), the hand's collision spheres' position error through its forward
   kinematics (cm^2), and the KL term;
4. sampling: ``--samples`` grasps per test object and scale, each the latent code of a random
   train success at that scale (the object-blind baseline's own picks) decoded with the test
   object's cloud: those grasps, adapted by the model to this object (``--latent prior``: z ~
   N(0, I) instead, which holds less, docs/learning.md); then (``--refine`` steps, 0: none) a
   test-time refinement of each with the penetration of the test object's observed cloud and the
   fingertip contact spheres' distance to it (the learned sample is its initialization: reported
   as its own row beside the raw one);
5. evaluation: ``datagen eval`` (the six-direction hold test, the job's protocol) of the samples,
   of an object-blind baseline (train successes drawn at random at the same scale; also refined
   the same way, the control for the refinement), of a retrieval baseline (the successes of the
   nearest train object, Chamfer distance) and of the dataset's own grasps of the same objects;
6. report: success with a 95% interval (bootstrap over the test objects: samples of one object
   are not independent), the difference to the object-blind baseline with its interval,
   penetration, and the successes' diversity, to OUT/report.md and OUT/report.json.

It measures whether the data teaches a model something an object-blind baseline lacks; it is a
small model on a small job, not a research result (docs/learning.md).
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import torch
from torch import nn

from datagen.eval.diversity import grasp_diversity
from datagen.hands import load_hand
from datagen.io import ObservationGraspDataset, points_of, read_job, read_observations

# One unit of the model's vector is about 1 cm of hand motion in every part (its squared error is a
# cheap stand-in for the hand's own point error): the object-centre offset in cm, the rotation's
# columns in tenths (0.1 ~ 1 cm at the fingertips, ~10 cm from the root), the joints in thirds of
# their half-range, the pregrasp and squeeze offsets in 0.2 rad.
U_SCALE, R_SCALE, J_SCALE, D_SCALE = 0.01, 0.1, 0.3, 0.2
POSES = ("pregrasp_qpos", "grasp_qpos", "squeeze_qpos")


# --- rotations ------------------------------------------------------------------------------------

def quat_to_matrix(q: torch.Tensor) -> torch.Tensor:
    """(N, 3, 3) rotation matrices of unit quaternions (N, 4) [w x y z]."""
    w, x, y, z = (q / q.norm(dim=-1, keepdim=True)).unbind(-1)
    return torch.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1).view(-1, 3, 3)


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(R).as_quat().T
    return np.stack([w, x, y, z], -1)


def rotation_6d(v: torch.Tensor) -> torch.Tensor:
    """(N, 3, 3) rotations from (N, 6) [first column, second column] by Gram-Schmidt."""
    x = v[:, :3] / v[:, :3].norm(dim=1, keepdim=True).clamp_min(1e-8)
    y = v[:, 3:] - (x * v[:, 3:]).sum(1, keepdim=True) * x
    y = y / y.norm(dim=1, keepdim=True).clamp_min(1e-8)
    return torch.stack([x, y, torch.cross(x, y, dim=1)], 2)


# --- grasp vectors <-> poses ------------------------------------------------------------------------

@dataclass
class Pose:
    """A batch of grasps as the model sees them: rotation (N, 3, 3), root position t (N, 3) m in
    the object frame, grasp joints (N, J) rad, pregrasp and squeeze joint offsets (N, J) rad."""

    R: torch.Tensor
    t: torch.Tensor
    joints: torch.Tensor
    pre_offset: torch.Tensor
    squeeze_offset: torch.Tensor

    def qpos(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(pregrasp, grasp, squeeze) qpos (N, 7 + J) float32 each, [x y z qw qx qy qz] + joints."""
        root = np.concatenate([self.t.detach().numpy(), matrix_to_quat(self.R.detach().double().numpy())], 1)
        j = self.joints.detach()
        return tuple(np.concatenate([root, q.numpy()], 1).astype(np.float32)
                     for q in (j - self.pre_offset.detach(), j, j + self.squeeze_offset.detach()))


class GraspCoder:
    """`Pose` <-> model vectors (N, 9 + 3 J): [6D rotation / R_SCALE, object centre in the root
    frame (centred) / U_SCALE, joints in [-1, 1] / J_SCALE, pregrasp and squeeze offsets / D_SCALE]."""

    def __init__(self, lower: np.ndarray, upper: np.ndarray):
        self.lo, self.hi = torch.tensor(lower, dtype=torch.float32), torch.tensor(upper, dtype=torch.float32)
        self.u_mean = torch.zeros(3)

    def pose_of(self, pre: torch.Tensor, grasp: torch.Tensor, squeeze: torch.Tensor) -> Pose:
        return Pose(quat_to_matrix(grasp[:, 3:7]), grasp[:, :3], grasp[:, 7:], grasp[:, 7:] - pre[:, 7:],
                    squeeze[:, 7:] - grasp[:, 7:])

    def encode(self, p: Pose) -> torch.Tensor:
        u = -(p.R.transpose(1, 2) @ p.t[:, :, None])[:, :, 0]  # the object's centre in the root frame
        joints = 2 * (p.joints - self.lo) / (self.hi - self.lo) - 1
        return torch.cat([p.R[:, :, 0] / R_SCALE, p.R[:, :, 1] / R_SCALE, (u - self.u_mean) / U_SCALE, joints / J_SCALE,
                          p.pre_offset / D_SCALE, p.squeeze_offset / D_SCALE], 1)

    def decode(self, v: torch.Tensor) -> Pose:
        """Differentiable; joints clamped to the limits."""
        J = len(self.lo)
        R = rotation_6d(v[:, :6])
        u = v[:, 6:9] * U_SCALE + self.u_mean
        joints = self.lo + ((v[:, 9:9 + J] * J_SCALE).clamp(-1, 1) + 1) / 2 * (self.hi - self.lo)
        return Pose(R, -(R @ u[:, :, None])[:, :, 0], joints, v[:, 9 + J:9 + 2 * J] * D_SCALE,
                    v[:, 9 + 2 * J:] * D_SCALE)


# --- the hand against a point cloud -------------------------------------------------------------------

class HandGeometry:
    """The hand's collision spheres and fingertip contact spheres of `Pose`s, through its FK."""

    def __init__(self, hand, train_spheres: int = 100):
        from datagen.synth.energies import contact_sphere_index

        self.hand = hand
        self.contact = contact_sphere_index(hand)  # (F,) the fingertip pads' spheres
        self.radii = hand.sphere_radii.float()
        step = max(1, hand.num_spheres // train_spheres)
        self.subset = torch.unique(torch.cat([torch.arange(0, hand.num_spheres, step), self.contact]))
        self.identity = torch.tensor([0, 0, 0, 1, 0, 0, 0], dtype=torch.float32)

    def spheres(self, p: Pose, subset: bool = False) -> tuple[torch.Tensor, torch.Tensor]:
        """Centres (N, S, 3) m in the object frame and radii (S,) m."""
        local, r = self.hand.spheres(self.identity, p.joints)  # (N, S, 3) in the root frame
        idx = self.subset if subset else slice(None)
        return (local[:, idx] @ p.R.transpose(1, 2)) + p.t[:, None], r[idx].float()


def signed_distance(q: torch.Tensor, pts: torch.Tensor, normals: torch.Tensor, k: int = 8) -> torch.Tensor:
    """(N, M) approximate signed distance (m, negative inside) of points q (N, M, 3) to a surface
    sampled by pts (N, P, 3) with outward normals (N, P, 3): the nearest point's distance, signed
    by the k nearest points' normals (a vote that a thin wall or a sparse sample flips less).
    Differentiable in q (the neighbours are found without gradient)."""
    N, M, P = q.shape[0], q.shape[1], pts.shape[1]
    with torch.no_grad():
        ik = torch.cdist(q, pts).topk(k, dim=2, largest=False).indices  # (N, M, k)
    flat = (ik + P * torch.arange(N)[:, None, None]).reshape(-1)
    near = pts.reshape(-1, 3)[flat].view(N, M, k, 3)
    diff = q[:, :, None] - near
    side = (diff * normals.reshape(-1, 3)[flat].view(N, M, k, 3)).sum(-1).mean(-1)
    d = diff[:, :, 0].norm(dim=-1)
    return torch.where(side < 0, -d, d)


def contact_terms(geo: HandGeometry, p: Pose, pts: torch.Tensor, normals: torch.Tensor,
                  subset: bool = True) -> tuple[torch.Tensor, torch.Tensor]:
    """Per grasp (N,): summed squared sphere penetration (cm^2) and summed squared contact-sphere
    gap to the surface (cm^2), against the cloud (pts, normals) (N, P, 3)."""
    return sphere_terms(geo, *geo.spheres(p, subset=subset), pts, normals, subset)


def sphere_terms(geo: HandGeometry, c: torch.Tensor, r: torch.Tensor, pts: torch.Tensor, normals: torch.Tensor,
                 subset: bool) -> tuple[torch.Tensor, torch.Tensor]:
    """`contact_terms` of sphere centres c (N, S, 3) and radii r (S,) (all spheres or the subset)."""
    pen = torch.relu(r - signed_distance(c, pts, normals)) / 0.01
    idx = torch.searchsorted(geo.subset, geo.contact) if subset else geo.contact
    gap = (signed_distance(c[:, idx], pts, normals) - r[idx]) / 0.01
    return (pen ** 2).sum(1), (gap ** 2).sum(1)


# --- the model ------------------------------------------------------------------------------------

def mlp(*sizes: int) -> nn.Sequential:
    layers = []
    for a, b in zip(sizes[:-1], sizes[1:]):
        layers += [nn.Linear(a, b), nn.ReLU()]
    return nn.Sequential(*layers[:-1])


class PointNet(nn.Module):
    """(B, P, 3) clouds in metres, object frame -> (B, F) features: a shared per-point MLP of the
    point and its offset from the cloud's centroid (the object frame's origin is the full surface's
    box centre; a partial view's centroid is not), max over points, and the centroid itself."""

    def __init__(self, features: int = 128):
        super().__init__()
        self.point = mlp(6, 32, 64, features)
        self.out = mlp(features + 3, features)

    def forward(self, pts: torch.Tensor) -> torch.Tensor:
        centre = pts.mean(1, keepdim=True)
        f = self.point(torch.cat([pts, pts - centre], 2) / 0.05).max(dim=1).values
        return self.out(torch.cat([torch.relu(f), centre[:, 0] / 0.05], 1))


class GraspCVAE(nn.Module):
    def __init__(self, dim: int, latent: int = 16, features: int = 128, hidden: int = 256):
        super().__init__()
        self.latent = latent
        self.cloud = PointNet(features)
        self.enc = mlp(dim + features, hidden, hidden, 2 * latent)
        self.dec = mlp(latent + features, hidden, hidden, dim)

    def forward(self, c: torch.Tensor, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Reconstruction (B, dim) of x (B, dim) given cloud features c (B, F), and the KL term."""
        mu, logvar = self.enc(torch.cat([x, c], 1)).chunk(2, dim=1)
        z = mu + torch.randn_like(mu) * (0.5 * logvar).exp()
        kl = -0.5 * (1 + logvar - mu ** 2 - logvar.exp()).sum(1).mean()
        return self.dec(torch.cat([z, c], 1)), kl

    def decode_prior(self, c: torch.Tensor, generator: torch.Generator | None = None) -> torch.Tensor:
        z = torch.randn(len(c), self.latent, generator=generator)
        return self.dec(torch.cat([z, c], 1))


# --- data -----------------------------------------------------------------------------------------

@dataclass
class TrainSet:
    """Successful train grasps of one or more jobs: model vectors x (N, D), their poses, the row of
    their observation obs_of (N,), and per observation row the model input clouds (K, V, P, 3)
    (V = 1 for the surface) and the surface points and normals (K, P', 3) for the contact terms."""

    x: torch.Tensor
    poses: Pose
    qpos: tuple[torch.Tensor, torch.Tensor, torch.Tensor]
    obs_of: torch.Tensor
    scale: torch.Tensor
    inputs: torch.Tensor
    surface: torch.Tensor
    normals: torch.Tensor


def model_input(obs: dict, args) -> torch.Tensor:
    """(V, P, 3) the clouds the model may see of one observation (``--input``)."""
    if args.input == "surface":
        return obs["points"][None, :args.points]
    return obs["view_points"][:, :args.points]  # every view: training draws one per step


def load_train(jobs: list[Path], coder: GraspCoder, args) -> TrainSet:
    xs, qs, obs_of, scale, inputs, surf, nrm = [], [], [], [], [], [], []
    for job in jobs:
        ds = ObservationGraspDataset(job, only_success=True, split="train", points=args.surface_points,
                                     view_points=args.points if args.input == "view" else 1)
        idx = torch.tensor([i for i, _ in ds.pairs], dtype=torch.long)
        qs.append([ds.grasps.poses[c][idx] for c in POSES])
        obs_of.append(torch.tensor([r for _, r in ds.pairs], dtype=torch.long) + len(surf))
        scale.append(ds.grasps.scale[idx])
        inputs += [model_input(o, args) for o in ds.observations]
        surf += [o["points"] for o in ds.observations]
        nrm += [o["normals"] for o in ds.observations]
    qpos = tuple(torch.cat([q[k] for q in qs]) for k in range(3))
    poses = coder.pose_of(*qpos)
    coder.u_mean = -(poses.R.transpose(1, 2) @ poses.t[:, :, None])[:, :, 0].mean(0)
    return TrainSet(coder.encode(poses), poses, qpos, torch.cat(obs_of), torch.cat(scale), torch.stack(inputs),
                    torch.stack(surf), torch.stack(nrm))


# --- training -------------------------------------------------------------------------------------

def pick_clouds(ts: TrainSet, o: torch.Tensor, n: int, gen: torch.Generator) -> torch.Tensor:
    """(B, n, 3) model inputs of observation rows o (B,): one view each (a random one), n random points."""
    clouds = ts.inputs[o, torch.randint(ts.inputs.shape[1], (len(o),), generator=gen)]
    return clouds[:, torch.randperm(clouds.shape[1], generator=gen)[:n]]


def train_step(model, coder, geo, ts: TrainSet, target_spheres, b, gen, args, ramp: float) -> dict:
    c = model.cloud(pick_clouds(ts, ts.obs_of[b], args.train_points, gen))
    rec, kl = model(c, ts.x[b])
    sph, _ = geo.spheres(coder.decode(rec), subset=True)
    terms = {"vector": ((rec - ts.x[b]) ** 2).sum(1).mean(), "kl": kl,
             "fk": (((sph - target_spheres[b]) / 0.01) ** 2).sum(-1).mean(1).mean()}
    return {"loss": terms["vector"] + args.w_fk * terms["fk"] + args.beta * ramp * kl, **terms}


def train(ts: TrainSet, coder: GraspCoder, geo: HandGeometry, args) -> tuple[GraspCVAE, list[dict]]:
    model = GraspCVAE(ts.x.shape[1])
    opt = torch.optim.Adam(model.parameters(), lr=args.lr)
    gen = torch.Generator().manual_seed(args.seed)
    with torch.no_grad():
        target_spheres = geo.spheres(ts.poses, subset=True)[0]  # (N, S', 3)
    log, t0, epoch = [], time.perf_counter(), 0
    while epoch < args.epochs and time.perf_counter() - t0 < 60 * args.minutes:
        ramp = min(1.0, (epoch + 1) / args.warmup)  # the KL term phased in
        tot: dict[str, float] = {}
        for b in torch.randperm(len(ts.x), generator=gen).split(args.batch):
            terms = train_step(model, coder, geo, ts, target_spheres, b, gen, args, ramp)
            opt.zero_grad()
            terms["loss"].backward()
            opt.step()
            for k, v in terms.items():
                tot[k] = tot.get(k, 0.0) + v.item() * len(b) / len(ts.x)
        epoch += 1
        if epoch % 25 == 0 or epoch == 1:
            log.append({"epoch": epoch, "s": round(time.perf_counter() - t0, 1), **tot})
            print(f"  epoch {epoch:4d} {log[-1]['s']:6.1f} s  " + "  ".join(f"{k} {v:.3f}" for k, v in tot.items()),
                  flush=True)
    log.append({"epoch": epoch, "s": round(time.perf_counter() - t0, 1), **tot})
    return model, log


# --- test-time refinement -------------------------------------------------------------------------

def refine(geo: HandGeometry, coder: GraspCoder, p: Pose, pts: torch.Tensor, normals: torch.Tensor,
           args) -> Pose:
    """``args.refine`` Adam steps on each grasp's vector: every collision sphere's squared
    penetration of the cloud (pts, normals) (N, P, 3), the fingertip contact spheres' squared gap,
    and a pull back to the start; the pregrasp and squeeze offsets kept."""
    v0 = coder.encode(p).detach()
    v = v0.clone().requires_grad_()
    opt = torch.optim.Adam([v], lr=args.refine_lr)
    for _ in range(args.refine):
        q = coder.decode(v)
        pen, gap = contact_terms(geo, q, pts, normals, subset=True)
        loss = (pen + gap).sum() + args.refine_anchor * ((v - v0) ** 2).sum()
        opt.zero_grad()
        loss.backward()
        opt.step()
    return coder.decode(v.detach())


# --- the grasps to evaluate -------------------------------------------------------------------------

@dataclass
class TestSet:
    """The test splits' object-scale rows: their eval table columns, model inputs (K, P, 3) and
    surface clouds with normals (K, P', 3)."""

    rows: dict
    inputs: torch.Tensor
    surface: torch.Tensor
    normals: torch.Tensor


def load_test(jobs: list[Path], args) -> TestSet:
    rows: dict = {"object_id": [], "object_scale_m": [], "object_path": []}
    inputs, surf, nrm = [], [], []
    for job in jobs:
        obs = read_observations(job, split="test")
        for r in range(obs.num_rows):
            o = ObservationGraspDataset._observation(obs, r, args.surface_points, args.points)
            rows["object_id"].append(o["object_id"])
            rows["object_scale_m"].append(float(o["object_scale_m"]))
            rows["object_path"].append(str(job / obs["object_path"][r].as_py()))
            inputs.append(model_input(o, args)[0])  # the first view (a camera direction drawn at random)
            surf.append(o["points"])
            nrm.append(o["normals"])
    if not inputs:
        sys.exit(f"{', '.join(map(str, jobs))}: no test-split observations to sample for")
    return TestSet(rows, torch.stack(inputs), torch.stack(surf), torch.stack(nrm))


def refined(geo, coder, p: Pose, test: TestSet, args, chunk: int = 128) -> Pose:
    """`refine` of ``args.samples`` grasps per test row against its row's cloud, ``chunk`` at a time."""
    row = torch.arange(len(test.inputs)).repeat_interleave(args.samples)
    parts = []
    for sl in torch.arange(len(row)).split(chunk):
        one = Pose(*(getattr(p, f)[sl] for f in Pose.__dataclass_fields__))
        parts.append(refine(geo, coder, one, test.surface[row[sl]], test.normals[row[sl]], args))
    return Pose(*(torch.cat([getattr(q, f) for q in parts]) for f in Pose.__dataclass_fields__))


def nearest_train_rows(ts: TrainSet, test: TestSet, n: int) -> np.ndarray:
    """Per test row, ``n`` indices into the train grasps (cycled): the successes of the train
    object and scale whose surface cloud is nearest (symmetric Chamfer distance, 256 points)."""
    train = ts.surface[:, :256]
    by_obs: dict = {}
    for i, r in enumerate(ts.obs_of.tolist()):
        by_obs.setdefault(r, []).append(i)
    have = sorted(by_obs)
    out = []
    for cloud in test.surface[:, :256]:
        d = torch.cdist(cloud[None].expand(len(have), -1, -1), train[have])
        idx = by_obs[have[int((d.min(2).values.mean(1) + d.min(1).values.mean(1)).argmin())]]
        out += [idx[k % len(idx)] for k in range(n)]
    return np.array(out)


def grasps_for_test(ts: TrainSet, test: TestSet, model: GraspCVAE, coder: GraspCoder, geo: HandGeometry,
                    args) -> dict[str, tuple]:
    """name -> (pregrasp, grasp, squeeze) (n, 7 + J) each, ``args.samples`` per test row."""
    model.eval()
    rng = np.random.default_rng(args.seed)
    scale = ts.scale.numpy()
    picks = torch.from_numpy(np.concatenate([rng.choice(np.flatnonzero(np.isclose(scale, s)), args.samples)
                                             for s in test.rows["object_scale_m"]]))
    blind = coder.pose_of(*(q[picks] for q in ts.qpos))
    with torch.no_grad():
        c = model.cloud(test.inputs).repeat_interleave(args.samples, 0)
        if args.latent == "prior":
            z = torch.randn(len(c), model.latent, generator=torch.Generator().manual_seed(args.seed + 1))
        else:  # the codes of the object-blind picks, on their own objects: those grasps, decoded for this one
            own = model.cloud(ts.inputs[ts.obs_of[picks], 0])
            z = model.enc(torch.cat([ts.x[picks], own], 1)).chunk(2, dim=1)[0]
        samples = coder.decode(model.dec(torch.cat([z, c], 1)))
    out = {"cvae": samples.qpos(), "blind": blind.qpos(),
           "nearest": tuple(q[nearest_train_rows(ts, test, args.samples)].numpy() for q in ts.qpos)}
    if args.refine:
        t0 = time.perf_counter()
        out["cvae_refined"] = refined(geo, coder, samples, test, args).qpos()
        out["blind_refined"] = refined(geo, coder, blind, test, args).qpos()
        print(f"refined {2 * len(picks)} grasps ({args.refine} steps) in {time.perf_counter() - t0:.0f} s", flush=True)
    return out


# --- evaluation and report ----------------------------------------------------------------------------

def grasp_table(test: TestSet, poses: tuple, per_row: int, hand: str, task: str) -> pa.Table:
    """The rows ``datagen eval`` reads (datagen/eval/table.py): ``per_row`` grasps per test row."""
    cols = {k: [v for v in vals for _ in range(per_row)] for k, vals in test.rows.items()}
    n, nq = len(cols["object_id"]), poses[0].shape[1]
    return pa.table({**cols, "hand": [hand] * n, "task": [task] * n,
                     **{name: pa.FixedSizeListArray.from_arrays(pa.array(p.reshape(-1), pa.float32()), nq)
                        for name, p in zip(POSES, poses)}})


def evaluate(table: pa.Table, out: Path, workers: int) -> pa.Table:
    """The table through ``datagen eval`` (a separate process: the same command a user runs)."""
    src = out.with_suffix(".in.parquet")
    pq.write_table(table, src)
    subprocess.run([sys.executable, "-m", "datagen.cli", "eval", str(src), "--out", str(out), "--allow-outside",
                    "--workers", str(workers)], check=True)
    return pq.read_table(out)


def rounded(scales) -> list[float]:
    """Scales (m) as join keys: float64, 6 decimals (the columns are float32 or float64)."""
    return np.round(np.asarray(scales, np.float64), 6).tolist()


def dataset_rows(jobs: list[Path], test: TestSet) -> pa.Table:
    """The jobs' own evaluated grasps of the test rows' objects and scales."""
    keys = set(zip(test.rows["object_id"], rounded(test.rows["object_scale_m"])))
    parts = []
    for job in jobs:
        data = read_job(job, columns=["object_id", "object_scale_m", "success", "penetration_m", "grasp_qpos",
                                      "reason", "split"])
        data = data.filter(pc.equal(data["split"], "test"))
        parts.append(data.filter(pa.array([k in keys for k in zip(
            data["object_id"].to_pylist(), rounded(data["object_scale_m"]))])))
    return pa.concat_tables(parts)


def by_object(t: pa.Table) -> dict:
    """{(object_id, scale): successes (n,) bool} of an evaluated table."""
    out: dict = {}
    for o, s, ok in zip(t["object_id"].to_pylist(), rounded(t["object_scale_m"]),
                        t["success"].to_pylist()):
        out.setdefault((o, s), []).append(bool(ok))
    return out


def bootstrap(groups: dict, keys: list, other: dict | None = None, reps: int = 4000, seed: int = 0) -> tuple:
    """95% interval of the pooled success rate (or of its difference to ``other``'s), resampling
    the test object-scale rows with replacement (their grasps are not independent)."""
    rng = np.random.default_rng(seed)
    ok = np.array([sum(groups.get(k, [])) for k in keys], float)
    n = np.array([len(groups.get(k, [])) for k in keys], float)
    ok2 = np.array([sum(other.get(k, [])) for k in keys], float) if other else None
    n2 = np.array([len(other.get(k, [])) for k in keys], float) if other else None
    stats = []
    for _ in range(reps):
        i = rng.integers(len(keys), size=len(keys))
        s = ok[i].sum() / max(n[i].sum(), 1)
        stats.append(s - ok2[i].sum() / max(n2[i].sum(), 1) if other else s)
    return tuple(np.percentile(stats, [2.5, 97.5]))


def summary(name: str, t: pa.Table, lo: np.ndarray, hi: np.ndarray, keys: list, blind: dict | None) -> dict:
    ok = np.asarray(t["success"].to_pylist(), bool)
    pen = np.asarray(t["penetration_m"].to_pylist(), float) * 1000
    q = np.asarray(t["grasp_qpos"].to_pylist(), float).reshape(len(ok), 7 + len(lo))
    d = grasp_diversity(q[ok], lo, hi)
    groups = by_object(t)
    diff = blind and {"diff_vs_blind": float(ok.mean() - np.mean([v for g in blind.values() for v in g])),
                      "diff_ci": list(bootstrap(groups, keys, blind))}
    return {"grasps": name, "n": len(ok), "success": float(ok.mean()), "success_ci": list(bootstrap(groups, keys)),
            **(diff or {}),
            "penetration_mm_mean": float(np.nanmean(pen)), "penetration_mm_p90": float(np.nanpercentile(pen, 90)),
            "reasons": {str(k): int(v) for k, v in zip(*np.unique(np.asarray(t["reason"].to_pylist(), str),
                                                                   return_counts=True))},
            "diversity_n": d.n, "pca": list(d.pca), "joint_entropy": d.joint_entropy}


NAMES = {"cvae": "CVAE samples (raw)", "cvae_refined": "CVAE samples + test-time refinement",
         "blind": "baseline: random train successes (object-blind)",
         "blind_refined": "baseline: object-blind + the same refinement",
         "nearest": "baseline: the nearest train object's successes (Chamfer)",
         "dataset": "the dataset's own grasps of the same objects"}


def report_lines(rows: list[dict], args, info: dict) -> list[str]:
    def pct(x):
        return "-" if x is None or math.isnan(x) else f"{100 * x:.1f}"

    out = ["| grasps | n | success % [95% CI] | vs object-blind, points [95% CI] | penetration mean / p90 (mm) | "
           "successes | PCA top 1 / 2 / 3 | joint entropy |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        pca = " / ".join("-" if math.isnan(x) else f"{x:.2f}" for x in r["pca"][:3])
        ent = "-" if math.isnan(r["joint_entropy"]) else f"{r['joint_entropy']:.2f}"
        lo, hi = r["success_ci"]
        diff = (f"{100 * r['diff_vs_blind']:+.1f} [{100 * r['diff_ci'][0]:+.1f}, {100 * r['diff_ci'][1]:+.1f}]"
                if "diff_ci" in r else "-")
        out.append(f"| {r['grasps']} | {r['n']} | {pct(r['success'])} [{pct(lo)}, {pct(hi)}] | {diff} | "
                   f"{r['penetration_mm_mean']:.1f} / {r['penetration_mm_p90']:.1f} | {r['diversity_n']} | {pca} | {ent} |")
    out += ["", "outcomes (`reason`): " + "; ".join(
        f"{r['grasps']}: " + ", ".join(f"{k} {v}" for k, v in sorted(r["reasons"].items(), key=lambda kv: -kv[1]))
        for r in rows)]
    return [f"jobs {', '.join(f'`{j}`' for j in info['jobs'])}: hand {info['hand']}, {info['train_grasps']} successful "
            f"train grasps on {info['train_rows']} object-scale rows; test: {info['test_rows']} object-scale rows, "
            f"{args.samples} samples each; input `{args.input}`; {info['epochs']} epochs in {info['train_s']:.0f} s "
            f"on {args.threads} thread(s); refinement {args.refine} steps; intervals: bootstrap over the test rows",
            ""] + out


def parse_args() -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("jobs", type=Path, nargs="+", help="finished jobs of one hand with observations and train and "
                    "test splits (trained on every train split, tested on every test split)")
    ap.add_argument("--out", type=Path, default=Path("learn"), help="where the tables and the report go")
    ap.add_argument("--minutes", type=float, default=10.0, help="training time limit")
    ap.add_argument("--epochs", type=int, default=3000, help="training epoch limit")
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--lr", type=float, default=2e-3, help="Adam's learning rate")
    ap.add_argument("--beta", type=float, default=0.2, help="KL weight (after the warm-up)")
    ap.add_argument("--warmup", type=int, default=30, help="epochs over which the KL term comes in")
    ap.add_argument("--w-fk", type=float, default=1.0, help="weight of the spheres' position error (cm^2)")
    ap.add_argument("--input", choices=("surface", "view"), default="surface",
                    help="the model's input: the full surface cloud, or one single-view depth cloud")
    ap.add_argument("--points", type=int, default=512, help="input cloud points kept per object (or per view)")
    ap.add_argument("--train-points", type=int, default=128, help="random input points per training step")
    ap.add_argument("--surface-points", type=int, default=512, help="surface points for the contact terms")
    ap.add_argument("--samples", type=int, default=16, help="grasps sampled per test object and scale")
    ap.add_argument("--latent", choices=("posterior", "prior"), default="posterior",
                    help="sampling's latent codes: those of random train successes at the scale (the object-blind "
                         "baseline's picks), or z ~ N(0, I)")
    ap.add_argument("--refine", type=int, default=100, help="test-time refinement steps (0: none)")
    ap.add_argument("--refine-lr", type=float, default=0.05, help="Adam's step in the grasp vector's units")
    ap.add_argument("--refine-anchor", type=float, default=0.1, help="weight of the pull back to the sample")
    ap.add_argument("--threads", type=int, default=1,
                    help="torch threads (1: on a shared machine more threads than free cores slow it 10-40x)")
    ap.add_argument("--workers", type=int, default=2, help="evaluation processes")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    if args.input == "view" and args.refine:
        ap.error("--refine reads the test object's full surface cloud and its normals: give --refine 0 with "
                 "--input view (a single view has no normals)")
    return args


def main() -> None:
    args = parse_args()
    torch.manual_seed(args.seed)
    torch.set_num_threads(args.threads)
    jobs, out = [j.resolve() for j in args.jobs], args.out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    hands = {json.loads((j / "job.json").read_text())["config"]["hand"] for j in jobs}
    if len(hands) != 1:
        sys.exit(f"the jobs are of different hands ({', '.join(sorted(hands))}): give jobs of one hand")
    hand_name = hands.pop()
    hand = load_hand(hand_name, base=jobs[0])
    lo, hi = hand.joint_lower.numpy(), hand.joint_upper.numpy()
    coder, geo = GraspCoder(lo, hi), HandGeometry(hand)
    ts = load_train(jobs, coder, args)
    if not len(ts.x):
        sys.exit(f"{', '.join(map(str, jobs))}: no successful train grasps with observations")
    task = read_job(jobs[0], columns=["task"])["task"][0].as_py()
    print(f"training on {len(ts.x)} successful train grasps of {len(ts.surface)} object-scale rows "
          f"({args.threads} threads, <= {args.minutes:g} min)", flush=True)
    model, log = train(ts, coder, geo, args)
    torch.save({"model": model.state_dict(), "u_mean": coder.u_mean, "args": vars(args)}, out / "model.pt")

    test = load_test(jobs, args)
    grasps = grasps_for_test(ts, test, model, coder, geo, args)
    print(f"evaluating {sum(len(p[0]) for p in grasps.values())} grasps in MuJoCo", flush=True)
    ev = {k: evaluate(grasp_table(test, p, args.samples, hand_name, task), out / f"{k}.parquet", args.workers)
          for k, p in grasps.items()}
    ev["dataset"] = dataset_rows(jobs, test)
    keys = list(zip(test.rows["object_id"], rounded(test.rows["object_scale_m"])))
    blind = by_object(ev["blind"])
    rows = [summary(NAMES[k], ev[k], lo, hi, keys, None if k in ("blind", "dataset") else blind)
            for k in NAMES if k in ev]
    info = {"jobs": [str(j) for j in jobs], "hand": hand_name, "train_grasps": len(ts.x),
            "train_rows": len(ts.surface), "test_rows": len(keys), "epochs": log[-1]["epoch"], "train_s": log[-1]["s"]}
    lines = report_lines(rows, args, info)
    print("\n".join(lines))
    (out / "report.md").write_text("\n".join(lines) + "\n")
    (out / "report.json").write_text(json.dumps({"info": info, "args": {k: str(v) for k, v in vars(args).items()},
                                                 "results": rows, "training": log}, indent=1, default=str))


if __name__ == "__main__":
    main()
