"""A reference learner: a conditional VAE of grasps given the object's point cloud, trained on a
job's train split, its samples on the test split's objects put through the same MuJoCo test.

    python examples/learn_grasps.py JOB_DIR --out learn/        # or: make learn LEARN_JOB=JOB_DIR

What it does, in plain torch (no project code inside the model):

1. data: `datagen.io.ObservationGraspDataset` pairs each successful train grasp with its object's
   observation at its scale (``observations/``: ``--points`` surface points, metres, object frame);
2. model: a PointNet encoder (shared per-point MLP, max-pool) of the cloud conditions a CVAE whose
   grasp vector is [root translation / 10 cm, root rotation as the first two columns of its matrix,
   joints mapped to [-1, 1] by the hand's limits, pregrasp and squeeze joint offsets / 0.2 rad];
   trained for ``--minutes`` (or ``--epochs``) with Adam on ``--threads`` CPU threads, each
   object and its grasp turned together by a random rotation per step (``--augment``);
3. sampling: ``--samples`` grasps per test object and scale, z ~ N(0, I), decoded to the three
   poses the MuJoCo test executes (pregrasp, grasp, squeeze; the root is shared, as in the data);
4. evaluation: ``datagen eval`` (the six-direction hold test, the job's protocol) of the samples,
   of a baseline that ignores the object (train successes drawn at random at the same scale),
   of one that retrieves the successes of the nearest train object (the clouds' Chamfer
   distance), and, for reference, the dataset's own grasps of the same objects;
5. report: success rate, penetration, and the successes' diversity (DexGraspBench's PCA, GraspQP's
   joint entropy: `datagen.eval.diversity`) of each, printed and written to OUT/report.md and
   OUT/report.json.

It measures whether the data teaches a model something the object-blind baseline lacks; it is a
small model on a small job, not a research result (docs/learning.md).
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import time
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

T_SCALE, D_SCALE = 0.1, 0.2  # metres and radians of one unit of the model's translation and joint offsets
POSES = ("pregrasp_qpos", "grasp_qpos", "squeeze_qpos")


# --- grasp vectors <-> qpos (pregrasp, grasp, squeeze) ----------------------------------------------

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


class GraspCoder:
    """(pregrasp, grasp, squeeze) qpos (N, 7 + J) each <-> model vectors (N, 9 + 3 J)."""

    def __init__(self, lower: np.ndarray, upper: np.ndarray):
        self.lo, self.hi = torch.tensor(lower, dtype=torch.float32), torch.tensor(upper, dtype=torch.float32)

    def encode(self, pre: torch.Tensor, grasp: torch.Tensor, squeeze: torch.Tensor,
               turn: torch.Tensor | None = None) -> torch.Tensor:
        """``turn`` (N, 3, 3): the grasps of the object turned by these rotations (augmentation)."""
        R = quat_to_matrix(grasp[:, 3:7])
        t = grasp[:, :3]
        if turn is not None:
            R, t = turn @ R, (turn @ t[:, :, None])[:, :, 0]
        joints = 2 * (grasp[:, 7:] - self.lo) / (self.hi - self.lo) - 1
        return torch.cat([t / T_SCALE, R[:, :, 0], R[:, :, 1], joints,
                          (grasp[:, 7:] - pre[:, 7:]) / D_SCALE, (squeeze[:, 7:] - grasp[:, 7:]) / D_SCALE], 1)

    def decode(self, v: torch.Tensor) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        J = len(self.lo)
        a, b = v[:, 3:6], v[:, 6:9]  # Gram-Schmidt: the nearest rotation's first two columns
        x = a / a.norm(dim=1, keepdim=True)
        y = b - (x * b).sum(1, keepdim=True) * x
        y = y / y.norm(dim=1, keepdim=True)
        R = torch.stack([x, y, torch.cross(x, y, dim=1)], 2).numpy().astype(np.float64)
        joints = self.lo + (v[:, 9:9 + J].clamp(-1, 1) + 1) / 2 * (self.hi - self.lo)
        root = np.concatenate([(v[:, :3] * T_SCALE).numpy(), matrix_to_quat(R)], 1)
        pre = joints - v[:, 9 + J:9 + 2 * J] * D_SCALE
        squeeze = joints + v[:, 9 + 2 * J:] * D_SCALE
        return tuple(np.concatenate([root, j.numpy()], 1).astype(np.float32) for j in (pre, joints, squeeze))


# --- the model ------------------------------------------------------------------------------------

def mlp(*sizes: int) -> nn.Sequential:
    layers = []
    for a, b in zip(sizes[:-1], sizes[1:]):
        layers += [nn.Linear(a, b), nn.ReLU()]
    return nn.Sequential(*layers[:-1])


class PointNet(nn.Module):
    """(B, P, 3) clouds in metres -> (B, F) features (shared per-point MLP, max over points)."""

    def __init__(self, features: int = 256):
        super().__init__()
        self.point = mlp(3, 64, 128, features)

    def forward(self, pts: torch.Tensor) -> torch.Tensor:
        return self.point(pts / T_SCALE).max(dim=1).values


class GraspCVAE(nn.Module):
    def __init__(self, dim: int, latent: int = 16, features: int = 256, hidden: int = 256):
        super().__init__()
        self.latent = latent
        self.cloud = PointNet(features)
        self.enc = mlp(dim + features, hidden, hidden, 2 * latent)
        self.dec = mlp(latent + features, hidden, hidden, dim)

    def forward(self, pts: torch.Tensor, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        c = self.cloud(pts)
        mu, logvar = self.enc(torch.cat([x, c], 1)).chunk(2, dim=1)
        z = mu + torch.randn_like(mu) * (0.5 * logvar).exp()
        recon = self.dec(torch.cat([z, c], 1))
        kl = -0.5 * (1 + logvar - mu ** 2 - logvar.exp()).sum(1).mean()
        return ((recon - x) ** 2).sum(1).mean(), kl

    @torch.no_grad()
    def sample(self, pts: torch.Tensor, n: int, generator: torch.Generator) -> torch.Tensor:
        c = self.cloud(pts).repeat_interleave(n, 0)
        z = torch.randn(len(c), self.latent, generator=generator)
        return self.dec(torch.cat([z, c], 1))


def random_rotations(n: int, generator: torch.Generator) -> torch.Tensor:
    """(n, 3, 3) rotations uniform on SO(3) (unit quaternions from a normal sample)."""
    return quat_to_matrix(torch.randn(n, 4, generator=generator))


def train(ds: ObservationGraspDataset, coder: GraspCoder, args) -> tuple[GraspCVAE, list[dict]]:
    clouds = torch.stack([o["points"] for o in ds.observations])  # (K, P, 3): each object and scale once
    obs_of = torch.tensor([r for _, r in ds.pairs])
    g = ds.grasps.poses
    idx = torch.tensor([i for i, _ in ds.pairs])
    poses = [g[c][idx] for c in POSES]
    x = coder.encode(*poses)
    model = GraspCVAE(x.shape[1])
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    gen = torch.Generator().manual_seed(args.seed)
    log, t0, epoch = [], time.perf_counter(), 0
    while epoch < args.epochs and time.perf_counter() - t0 < 60 * args.minutes:
        perm = torch.randperm(len(x), generator=gen)
        beta = args.beta * min(1.0, (epoch + 1) / 50)  # KL warm-up
        tot = [0.0, 0.0]
        for b in perm.split(args.batch):
            pts = clouds[obs_of[b]]
            pts = pts[:, torch.randperm(pts.shape[1], generator=gen)[:args.train_points]]  # a random subset
            xb = x[b]
            if args.augment:  # object and grasp turned together: the same grasp of a turned object
                turn = random_rotations(len(b), gen)
                pts, xb = pts @ turn.transpose(1, 2), coder.encode(*(p[b] for p in poses), turn=turn)
            rec, kl = model(pts, xb)
            loss = rec + beta * kl
            opt.zero_grad()
            loss.backward()
            opt.step()
            tot[0] += rec.item() * len(b)
            tot[1] += kl.item() * len(b)
        epoch += 1
        if epoch % 50 == 0 or epoch == 1:
            log.append({"epoch": epoch, "s": round(time.perf_counter() - t0, 1),
                        "recon": tot[0] / len(x), "kl": tot[1] / len(x)})
            print(f"  epoch {epoch:5d}  {log[-1]['s']:6.1f} s  recon {log[-1]['recon']:.3f}  kl {log[-1]['kl']:.2f}",
                  flush=True)
    log.append({"epoch": epoch, "s": round(time.perf_counter() - t0, 1), "recon": tot[0] / len(x),
                "kl": tot[1] / len(x)})
    return model, log


# --- evaluation -----------------------------------------------------------------------------------

def nearest_train_grasps(ds: ObservationGraspDataset, clouds: torch.Tensor, test_obs: pa.Table, n: int) -> np.ndarray:
    """Per test row, ``n`` indices into ``ds.grasps`` (cycled): the successes of the train object
    and scale whose surface cloud is nearest its cloud (symmetric Chamfer distance, 256 points)."""
    train = torch.stack([o["points"][:256] for o in ds.observations])
    by_obs: dict = {}
    for i, r in ds.pairs:
        by_obs.setdefault(r, []).append(i)
    have = sorted(by_obs)
    out = []
    for cloud in clouds[:, :256]:
        d = torch.cdist(cloud[None].expand(len(have), -1, -1), train[have])
        chamfer = d.min(2).values.mean(1) + d.min(1).values.mean(1)
        idx = by_obs[have[int(chamfer.argmin())]]
        out += [idx[k % len(idx)] for k in range(n)]
    return np.array(out)


def grasp_table(job: Path, obs: pa.Table, poses: tuple, per_row: int, hand: str, task: str) -> pa.Table:
    """The rows ``datagen eval`` reads (datagen/eval/table.py): ``per_row`` grasps per observation row."""
    rep = np.repeat(np.arange(obs.num_rows), per_row)
    cols = {c: [obs[c][int(i)].as_py() for i in rep] for c in ("object_id", "object_scale_m")}
    cols["object_path"] = [str(job / obs["object_path"][int(i)].as_py()) for i in rep]
    nq = poses[0].shape[1]
    return pa.table({**cols, "hand": [hand] * len(rep), "task": [task] * len(rep),
                     **{name: pa.FixedSizeListArray.from_arrays(pa.array(p.reshape(-1), pa.float32()), nq)
                        for name, p in zip(POSES, poses)}})


def evaluate(table: pa.Table, out: Path, workers: int) -> pa.Table:
    """The table through ``datagen eval`` (a separate process: the same command a user runs)."""
    src, dst = out.with_suffix(".in.parquet"), out
    pq.write_table(table, src)
    subprocess.run([sys.executable, "-m", "datagen.cli", "eval", str(src), "--out", str(dst), "--allow-outside",
                    "--workers", str(workers)], check=True)
    return pq.read_table(dst)


def summary(name: str, t: pa.Table, lo: np.ndarray, hi: np.ndarray) -> dict:
    ok = np.asarray(t["success"].to_pylist(), bool)
    pen = np.asarray(t["penetration_m"].to_pylist(), float) * 1000
    q = np.asarray(t["grasp_qpos"].to_pylist(), float)
    d = grasp_diversity(q[ok], lo, hi)
    return {"grasps": name, "n": len(ok), "success": float(ok.mean()) if len(ok) else math.nan,
            "penetration_mm_mean": float(np.nanmean(pen)) if len(pen) else math.nan,
            "penetration_mm_p90": float(np.nanpercentile(pen, 90)) if len(pen) else math.nan,
            "reasons": {str(k): int(v) for k, v in zip(*np.unique(np.asarray(t["reason"].to_pylist(), str),
                                                                   return_counts=True))},
            "diversity_n": d.n, "pca": list(d.pca), "joint_entropy": d.joint_entropy}


def report_lines(rows: list[dict], args, info: dict) -> list[str]:
    out = ["| grasps | n | success | penetration mean / p90 (mm) | successes | PCA top 1 / 2 / 3 (successes) | "
           "joint entropy (successes) |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        pca = " / ".join("-" if math.isnan(x) else f"{x:.2f}" for x in r["pca"][:3])
        ent = "-" if math.isnan(r["joint_entropy"]) else f"{r['joint_entropy']:.2f}"
        out.append(f"| {r['grasps']} | {r['n']} | {r['success']:.1%} | {r['penetration_mm_mean']:.1f} / "
                   f"{r['penetration_mm_p90']:.1f} | {r['diversity_n']} | {pca} | {ent} |")
    out += ["", "outcomes (`reason`): " + "; ".join(
        f"{r['grasps']}: " + ", ".join(f"{k} {v}" for k, v in sorted(r["reasons"].items(), key=lambda kv: -kv[1]))
        for r in rows)]
    return [f"job `{info['job']}`: hand {info['hand']}, {info['train_grasps']} successful train grasps on "
            f"{info['train_objects']} object-scale pairs; test: {info['test_rows']} object-scale pairs, "
            f"{args.samples} samples each; {info['epochs']} epochs in {info['train_s']:.0f} s on {args.threads} "
            f"thread(s)", ""] + out


def parse_args() -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("job", type=Path, help="a finished job with observations and a train and a test split")
    ap.add_argument("--out", type=Path, default=Path("learn"), help="where the tables and the report go")
    ap.add_argument("--minutes", type=float, default=10.0, help="training time limit")
    ap.add_argument("--epochs", type=int, default=3000, help="training epoch limit")
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--beta", type=float, default=0.02, help="KL weight (after a 50-epoch warm-up)")
    ap.add_argument("--points", type=int, default=1024, help="surface points of each cloud kept")
    ap.add_argument("--train-points", type=int, default=512, help="random points of the cloud per training step")
    ap.add_argument("--augment", type=int, default=1,
                    help="1: turn each training object and its grasp by a random rotation (0: as stored)")
    ap.add_argument("--samples", type=int, default=4, help="grasps sampled per test object and scale")
    ap.add_argument("--threads", type=int, default=2, help="torch threads and evaluation processes")
    ap.add_argument("--seed", type=int, default=0)
    return ap.parse_args()


def grasps_for_test(ds: ObservationGraspDataset, model: GraspCVAE, coder: GraspCoder, test_obs: pa.Table,
                args) -> dict[str, tuple]:
    """name -> (pregrasp, grasp, squeeze) (n, 7 + J) each, ``args.samples`` per test row: the
    model's samples, random train successes at the row's scale (object-blind), and the nearest
    train object's successes."""
    clouds = torch.from_numpy(np.stack([p[:args.points] for p in points_of(test_obs["surface_points_m"])]))
    model.eval()
    samples = coder.decode(model.sample(clouds, args.samples, torch.Generator().manual_seed(args.seed + 1)))
    rng = np.random.default_rng(args.seed)
    g, train_idx = ds.grasps.poses, np.array([i for i, _ in ds.pairs])
    scale = ds.grasps.scale.numpy()[train_idx]
    picks = np.concatenate([rng.choice(np.flatnonzero(np.isclose(scale, s)), args.samples)
                            for s in test_obs["object_scale_m"].to_numpy()])
    near = nearest_train_grasps(ds, clouds, test_obs, args.samples)
    return {"cvae": samples, "baseline": tuple(g[c][train_idx[picks]].numpy() for c in POSES),
            "nearest": tuple(g[c][near].numpy() for c in POSES)}


def dataset_rows(job: Path, test_obs: pa.Table) -> pa.Table:
    """The job's own evaluated grasps of the test rows' objects and scales."""
    keys = set(zip(test_obs["object_id"].to_pylist(), np.round(test_obs["object_scale_m"].to_numpy(), 6).tolist()))
    data = read_job(job, columns=["object_id", "object_scale_m", "success", "penetration_m", "grasp_qpos", "reason",
                                  "split"])
    data = data.filter(pc.equal(data["split"], "test"))
    return data.filter(pa.array([k in keys for k in zip(data["object_id"].to_pylist(),
                                                         np.round(data["object_scale_m"].to_numpy(), 6).tolist())]))


def main() -> None:
    args = parse_args()
    torch.manual_seed(args.seed)
    torch.set_num_threads(args.threads)
    job, out = args.job.resolve(), args.out.resolve()
    out.mkdir(parents=True, exist_ok=True)

    ds = ObservationGraspDataset(job, only_success=True, split="train", points=args.points, view_points=1)
    if not len(ds):
        sys.exit(f"{job}: no successful train grasps with observations (a job with a train split and observations)")
    hand_name, task = json.loads((job / "job.json").read_text())["config"]["hand"], ds.grasps.task[0]
    hand = load_hand(hand_name, base=job)
    lo, hi = hand.joint_lower.numpy(), hand.joint_upper.numpy()
    coder = GraspCoder(lo, hi)
    print(f"training on {len(ds)} successful train grasps of {len(ds.observations)} object-scale pairs "
          f"({args.threads} threads, <= {args.minutes:g} min)", flush=True)
    model, log = train(ds, coder, args)

    test_obs = read_observations(job, split="test", columns=["object_id", "object_scale_m", "object_path",
                                                             "surface_points_m"])
    if not test_obs.num_rows:
        sys.exit(f"{job}: no test-split observations to sample for")
    grasps = grasps_for_test(ds, model, coder, test_obs, args)
    print(f"evaluating {sum(len(p[0]) for p in grasps.values())} grasps in MuJoCo", flush=True)
    ev = {k: evaluate(grasp_table(job, test_obs, p, args.samples, hand_name, task), out / f"{k}.parquet", args.threads)
          for k, p in grasps.items()}
    rows = [summary("CVAE samples", ev["cvae"], lo, hi),
            summary("baseline: random train successes (object-blind)", ev["baseline"], lo, hi),
            summary("baseline: the nearest train object's successes (cloud Chamfer distance)", ev["nearest"], lo, hi),
            summary("dataset's own grasps (synthesized, same objects)", dataset_rows(job, test_obs), lo, hi)]
    info = {"job": str(job), "hand": hand_name, "train_grasps": len(ds), "train_objects": len(ds.observations),
            "test_rows": test_obs.num_rows, "epochs": log[-1]["epoch"], "train_s": log[-1]["s"]}
    lines = report_lines(rows, args, info)
    print("\n".join(lines))
    (out / "report.md").write_text("\n".join(lines) + "\n")
    (out / "report.json").write_text(json.dumps({"info": info, "args": {k: str(v) for k, v in vars(args).items()},
                                                 "results": rows, "training": log}, indent=1, default=str))


if __name__ == "__main__":
    main()
