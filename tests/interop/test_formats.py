"""DexGraspBench export and import, and BODex import, checked by forward kinematics: the peer's
hand (rebuilt from the Menagerie MJCFs by MuJoCo, tests/interop/peer_models.py) posed from an
exported file puts every fingertip within 1 mm of where this project's kinematics put it;
imported files come back to the same fingertips in our object frame."""

from __future__ import annotations

import json
import os
from pathlib import Path

import mujoco
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import torch
import trimesh

from datagen.cli import main
from datagen.hands.load import available_hands
from datagen.objects import layout

from tests.workers.conftest import cache_dir, mesh_source  # noqa: F401 - fixtures

from .peer_models import PEER_FACTS, peer_model

pytestmark = pytest.mark.mujoco
HANDS = [h for h in PEER_FACTS if h in available_hands()]
POSES = ("pregrasp_qpos", "grasp_qpos", "squeeze_qpos")
TOL_M = 1e-3


@pytest.fixture(scope="module")
def hands():
    from datagen.hands import load_hand

    return {h: load_hand(h, dtype=torch.float64) for h in HANDS}


def _box_entry(root: Path) -> Path:
    """A processed object: one box piece, normalized units (half-diagonal 1)."""
    entry = root / "objects" / "box"
    (entry / layout.PIECES_DIR).mkdir(parents=True)
    box = trimesh.creation.box((1.2, 0.8, 0.6))
    box.apply_scale(1 / np.linalg.norm(box.extents / 2))
    box.export(entry / layout.PIECES_DIR / layout.PIECE.format(i=0))
    meta = {"meta_version": layout.META_VERSION, "object_id": "box", "status": "ok", "mesh_sha256": "0" * 64,
            "config_hash": "test", "piece_volumes": [float(box.volume)]}
    (entry / layout.META).write_text(json.dumps(meta))
    return entry


def _random_poses(hand, n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, 3, 7 + J): random roots and joints within limits (three different poses per grasp)."""
    lo, hi = hand.joint_lower.numpy(), hand.joint_upper.numpy()
    q = rng.normal(size=(n, 3, 4))
    root = np.concatenate([rng.normal(scale=0.1, size=(n, 3, 3)), q / np.linalg.norm(q, axis=-1, keepdims=True)], -1)
    return np.concatenate([root, lo + rng.uniform(size=(n, 3, len(lo))) * (hi - lo)], -1)


def _table(path: Path, hand: str, poses: np.ndarray, scale: float = 0.08) -> Path:
    n = len(poses)
    cols = {"grasp_id": [f"g{i}" for i in range(n)], "object_id": ["box"] * n, "object_scale_m": [scale] * n,
            "object_path": ["objects/box"] * n, "hand": [hand] * n, "task": ["force_closure"] * n}
    for j, k in enumerate(POSES):
        cols[k] = pa.array(poses[:, j].astype(np.float32).tolist(), type=pa.list_(pa.float32()))
    pq.write_table(pa.table(cols), path)
    return path


def _shared_links(model: mujoco.MjModel, hand) -> list[str]:
    """Our links that the peer's model has too (the Shadow E3M5's forearm and wrist it has not)."""
    return [n for n in hand.link_names if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, f"peer_{n}") >= 0]


def _our_tips(hand, pose: np.ndarray, links: list[str] | None = None) -> np.ndarray:
    """(F [+ L], 3): the fingertip points, then the origins of ``links``, by our kinematics."""
    p = torch.as_tensor(np.asarray(pose, dtype=np.float64))
    out = [hand.fingertip_points(p[:7], p[7:]).numpy()]
    if links:
        T = hand.link_poses(p[None, :7], p[None, 7:])
        out.append(np.stack([T[n][0, :3, 3].numpy() for n in links]))
    return np.concatenate(out)


def _peer_tips(model: mujoco.MjModel, hand, qpos: np.ndarray, links: list[str] | None = None) -> np.ndarray:
    """The same points by MuJoCo's kinematics of the peer's model at its qpos."""
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    out = []
    for name in hand.fingertip_names:
        tip = hand.spec.fingertips[name]
        b = model.body(f"peer_{tip.link}").id
        out.append(data.xpos[b] + data.xmat[b].reshape(3, 3) @ np.asarray(tip.point))
    out += [data.xpos[model.body(f"peer_{n}").id] for n in links or ()]
    return np.array(out)


@pytest.fixture(scope="module")
def exported(hands, tmp_path_factory):
    """hand -> (table rows by grasp_id, export directory)."""
    out = {}
    for name, hand in hands.items():
        root = tmp_path_factory.mktemp(f"export_{name}")
        _box_entry(root)
        poses = _random_poses(hand, 4, np.random.default_rng(7))
        table = _table(root / "grasps.parquet", name, poses)
        assert main(["export", str(table), "--format", "dexgraspbench", "--out", str(root / "dgb")]) == 0
        out[name] = ({r["grasp_id"]: r for r in pq.read_table(table).to_pylist()}, root / "dgb")
    return out


@pytest.mark.parametrize("name", HANDS)
def test_export_layout_and_fingertips(name, hands, exported):
    hand, (rows, out) = hands[name], exported[name]
    files = sorted((out / "graspdata").rglob("*.npy"))
    assert len(files) == len(rows)
    assert {f.parent.name for f in files} == {"scale008_pose000"}
    model = peer_model(name)
    links = _shared_links(model, hand)
    assert len(links) >= len(hand.link_names) - 2  # all but E3M5's forearm and wrist
    worst = 0.0
    for f in files:
        d = np.load(f, allow_pickle=True).item()
        row = rows[d["grasp_id"]]
        obj = Path(d["obj_path"])
        assert sorted(p.name for p in (obj / "urdf" / "meshes").iterdir()) == ["convex_piece_0.obj"]
        assert (obj / "mesh" / "simplified.obj").is_file()
        info = json.loads((obj / "info" / "simplified.json").read_text())
        assert info["mass"] / (info["density"] * info["scale"] ** 3) == pytest.approx(
            trimesh.load(obj / "urdf" / "meshes" / "convex_piece_0.obj").volume, rel=1e-6)
        assert d["obj_scale"] == pytest.approx(0.08) and np.allclose(d["obj_pose"], [0, 0, 0, 1, 0, 0, 0])
        for k in POSES:
            assert d[k].dtype == np.float32 and d[k].shape == (model.nq,)
            err = np.linalg.norm(_peer_tips(model, hand, d[k], links) - _our_tips(hand, row[k], links), axis=-1).max()
            worst = max(worst, err)
    assert worst < TOL_M, f"{name}: fingertips and bodies {worst * 1000:.3f} mm apart"


@pytest.mark.parametrize("name", HANDS)
def test_import_of_moved_and_rescaled_peer_files(name, hands, exported, tmp_path):
    """The exported files, rewritten as a peer would hold them (the object's pieces in their own
    units and frame, obj_scale and a world obj_pose), import back to our fingertips."""
    hand, (rows, out) = hands[name], exported[name]
    rng = np.random.default_rng(3)
    offset, k = np.array([0.3, -0.2, 0.5]), 4.0  # peer mesh = ours / k + offset
    obj = tmp_path / "peer_objects" / "boxy"
    (obj / "urdf" / "meshes").mkdir(parents=True)
    src = next((out / "objects").iterdir())
    piece = trimesh.load(src / "urdf" / "meshes" / "convex_piece_0.obj", force="mesh")
    piece.apply_scale(1 / k)
    piece.apply_translation(offset)
    piece.export(obj / "urdf" / "meshes" / "convex_piece_0.obj")
    q = rng.normal(size=4)
    T_wo = np.eye(4)
    T_wo[:3, :3] = trimesh.transformations.quaternion_matrix(q / np.linalg.norm(q))[:3, :3]
    T_wo[:3, 3] = [0.1, 0.2, -0.3]
    from datagen.interop import matrix_to_pose7, pose7_to_matrix

    peer_dir = tmp_path / "graspdata"
    peer_dir.mkdir()
    for f in sorted((out / "graspdata").rglob("*.npy")):
        d = np.load(f, allow_pickle=True).item()
        scale = d["obj_scale"] * k
        # object point x (ours, metres) = (peer mesh - offset) * k * 0.08 = peer_local - offset * scale
        shift = np.eye(4)
        shift[:3, 3] = offset * scale
        for key in POSES:
            qp = d[key].astype(np.float64)
            qp[:7] = matrix_to_pose7(T_wo @ shift @ pose7_to_matrix(qp[:7]))
            d[key] = qp.astype(np.float32)
        d.update(obj_path=str(obj), obj_scale=scale, obj_pose=matrix_to_pose7(T_wo))
        np.save(peer_dir / f.name, d, allow_pickle=True)
    table = tmp_path / "imported.parquet"
    assert main(["import", "--format", "dexgraspbench", str(peer_dir), "--hand", name, "--out", str(table)]) == 0
    t = pq.read_table(table)
    assert t.schema.metadata[b"datagen.schema"] == b"grasps"
    got = t.to_pylist()
    assert len(got) == len(rows)
    files = sorted(peer_dir.glob("*.npy"))
    worst = 0.0
    for r, f in zip(got, files):
        ref = rows[np.load(f, allow_pickle=True).item()["grasp_id"]]
        assert r["object_scale_m"] == pytest.approx(0.08, rel=1e-5)
        assert r["joint_names"] == list(hand.joint_names)
        assert (table.parent / r["object_path"] / layout.META).is_file()
        for key in POSES:
            worst = max(worst, np.linalg.norm(_our_tips(hand, r[key]) - _our_tips(hand, ref[key]), axis=-1).max())
    assert worst < TOL_M, f"{name}: imported fingertips {worst * 1000:.3f} mm from the originals"


def test_imported_grasps_evaluate(hands, exported, tmp_path):
    name = HANDS[0] if HANDS else pytest.skip("no peer hand installed (make hands)")
    _, out = exported[name]
    table = tmp_path / "imported.parquet"
    first = sorted((out / "graspdata").rglob("*.npy"))[0]
    assert main(["import", "--format", "dexgraspbench", str(first), "--hand", name, "--out", str(table)]) == 0
    assert main(["eval", str(table), "--out", str(tmp_path / "ev.parquet")]) == 0
    (row,) = pq.read_table(tmp_path / "ev.parquet").to_pylist()
    assert row["reason"]  # random poses: any verdict, but evaluated


def test_hand_the_peer_lacks_is_refused(tmp_path, capsys):
    _box_entry(tmp_path)
    table = _table(tmp_path / "g.parquet", "shadow", np.tile([0, 0, 0, 1.0] + [0.0] * 27, (1, 3, 1)))
    assert main(["export", str(table), "--out", str(tmp_path / "o")]) == 2
    assert "DexGraspBench has no model of it" in capsys.readouterr().err


def _peer_xml(name: str) -> Path:
    """The peer's own hand XML in the DexGraspBench checkout DEXGRASPBENCH_DIR names (skips
    without one; LEAP's includes MuJoCo Menagerie's, its third_party submodule)."""
    root = os.environ.get("DEXGRASPBENCH_DIR")
    if not root:
        pytest.skip("set DEXGRASPBENCH_DIR to a DexGraspBench checkout (and make hands)")
    xml = Path(root) / "assets" / "hand" / ("shadow" if name == "shadow_e3m5" else name) / "right_hand.xml"
    menagerie = Path(root) / "third_party" / "mujoco_menagerie" / "leap_hand" / "right_hand.xml"
    if not xml.is_file() or (name == "leap" and not menagerie.is_file()):
        pytest.skip(f"{xml} (or the Menagerie file it includes) not found")
    return xml


@pytest.mark.parametrize("name", HANDS)
def test_export_against_the_peers_own_xml(name, hands, exported):
    """With DEXGRASPBENCH_DIR pointing at a DexGraspBench checkout, its own hand XMLs check the
    export: every body the two models share and every fingertip within 1 mm."""
    xml = _peer_xml(name)
    hand, (rows, out) = hands[name], exported[name]
    model = peer_model(name, xml)
    links = _shared_links(model, hand)
    assert len(links) >= len(hand.link_names) - 2
    worst = 0.0
    for f in sorted((out / "graspdata").rglob("*.npy")):
        d = np.load(f, allow_pickle=True).item()
        for k in POSES:
            ours = _our_tips(hand, rows[d["grasp_id"]][k], links)
            worst = max(worst, np.linalg.norm(_peer_tips(model, hand, d[k], links) - ours, axis=-1).max())
    assert worst < TOL_M, f"{name}: fingertips and bodies {worst * 1000:.3f} mm apart"


def _rot(q_wxyz) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    q = np.asarray(q_wxyz, dtype=np.float64)
    return Rotation.from_quat(q[[1, 2, 3, 0]] / np.linalg.norm(q)).as_matrix()


# BODex's joint order (its kinematics': Shadow's thumb block first), by our joint names
BODEX_ORDER = {"shadow_e3m5": [f"rh_TH{j}" for j in ("J5", "J4", "J3", "J2", "J1")]
               + [f"rh_{f}J{j}" for f, n in (("FF", 4), ("MF", 4), ("RF", 4), ("LF", 5)) for j in range(n, 0, -1)]}


def _bodex_pose(name: str, dgb: np.ndarray) -> np.ndarray:
    """A DexGraspBench pose back in BODex's raw convention: the inverse of DexGraspBench's own
    BODex conversion (its src/task/convert_format.py: Shadow's thumb block first and the palm
    0.034 m up z, Allegro's palm rotated by quat (0 1 0 1), LEAP's by (0 1 0 0) and 0.1 m up z)."""
    from scipy.spatial.transform import Rotation

    p, R = dgb[:3], _rot(dgb[3:7])
    joints = dgb[7:]
    if name == "shadow_e3m5":
        p, joints = p + R @ [0, 0, 0.034], np.concatenate([joints[17:], joints[:17]])
    elif name == "allegro":
        R = R @ _rot([0, 1, 0, 1])
    else:
        p, R = p + R @ [0, 0, 0.1], R @ _rot([0, 1, 0, 0])
    q = Rotation.from_matrix(R).as_quat()[[3, 0, 1, 2]]
    return np.concatenate([p, q, joints])


@pytest.mark.parametrize("name", HANDS)
def test_bodex_import(name, hands, exported, tmp_path):
    """BODex raw files (one per object: robot_pose (1, N, 3, 7 + J), a scene config it names by a
    path inside BODex's tree) import to the fingertips of the grasps they were made from."""
    hand, (rows, out) = hands[name], exported[name]
    files = sorted((out / "graspdata").rglob("*.npy"))
    data = [np.load(f, allow_pickle=True).item() for f in files]
    content = tmp_path / "content"
    (content / "scene_cfg").mkdir(parents=True)
    obj = Path(data[0]["obj_path"])
    scene = {"task": {"obj_name": "box"},
             "scene": {"box": {"file_path": str(Path("..") / "objs" / "box" / "urdf" / "coacd.urdf"),
                               "scale": [data[0]["obj_scale"]], "pose": np.array([0, 0, 0, 1.0, 0, 0, 0])}}}
    import shutil

    shutil.copytree(obj, content / "objs" / "box")
    np.save(content / "scene_cfg" / "box.npy", scene, allow_pickle=True)
    robot_pose = np.array([[[_bodex_pose(name, d[k].astype(np.float64)) for k in POSES] for d in data]])
    raw = tmp_path / "raw" / "box_grasp.npy"
    raw.parent.mkdir()
    np.save(raw, {"robot_pose": robot_pose.astype(np.float32),
                  "scene_path": ["/elsewhere/BODex/src/curobo/content/scene_cfg/box.npy"]}, allow_pickle=True)
    table = tmp_path / "bodex.parquet"
    args = ["import", "--format", "bodex", str(raw), "--hand", name, "--out", str(table)]
    assert main(args) == 2  # the scene path is BODex's: found only under --root
    assert main(args + ["--root", str(content)]) == 0
    got = pq.read_table(table).to_pylist()
    assert len(got) == len(data)
    worst = 0.0
    for r, d in zip(got, data):
        ref = rows[d["grasp_id"]]
        for key in POSES:
            worst = max(worst, np.linalg.norm(_our_tips(hand, r[key]) - _our_tips(hand, ref[key]), axis=-1).max())
    assert worst < TOL_M, f"{name}: BODex fingertips {worst * 1000:.3f} mm from the originals"

    # a file that names its joints (BODex's URDF names, typed here from its URDFs and configs)
    # is read by name, whatever the order
    urdf_names = {"shadow_e3m5": [j for j in BODEX_ORDER["shadow_e3m5"]],
                  "allegro": [f"joint_{i}.0" for i in range(16)],
                  "leap": ["j1", "j0", "j2", "j3", "j5", "j4", "j6", "j7", "j9", "j8", "j10", "j11",
                           "j12", "j13", "j14", "j15"]}[name]
    perm = np.random.default_rng(5).permutation(len(urdf_names))
    shuffled = np.concatenate([robot_pose[..., :7], robot_pose[..., 7:][..., perm]], axis=-1)
    np.save(raw, {"robot_pose": shuffled.astype(np.float32), "joint_names": [urdf_names[i] for i in perm],
                  "scene_path": ["/elsewhere/BODex/src/curobo/content/scene_cfg/box.npy"]}, allow_pickle=True)
    assert main(args + ["--root", str(content)]) == 0
    again = pq.read_table(table).to_pylist()
    assert [r["grasp_qpos"] for r in again] == [r["grasp_qpos"] for r in got]
    np.save(raw, {"robot_pose": shuffled.astype(np.float32), "joint_names": ["nope"] * len(perm),
                  "scene_path": ["/elsewhere/BODex/src/curobo/content/scene_cfg/box.npy"]}, allow_pickle=True)
    assert main(args + ["--root", str(content)]) == 2


@pytest.fixture(scope="module")
def e3m5_job(tmp_path_factory, mesh_source, cache_dir):  # noqa: F811 - fixtures from tests.workers
    if "shadow_e3m5" not in HANDS:
        pytest.skip("shadow_e3m5 needs make hands")
    from tests.workers.conftest import tiny_config
    from tests.workers.test_shard import run_all

    cfg = tiny_config(mesh_source, hand="shadow_e3m5", count=1, grasps_per_object=2)
    return run_all(tmp_path_factory.mktemp("e3m5job") / "job", cfg, cache_dir).path


def test_export_of_a_job_directory(e3m5_job, hands, tmp_path):
    """`datagen export JOB`: the job's rows (object_path relative to the job) come out as files
    whose peer hand puts the fingertips on ours, and whose objects are the job's pieces."""
    from datagen.io import read_job

    out = tmp_path / "dgb"
    assert main(["export", str(e3m5_job), "--format", "dexgraspbench", "--out", str(out)]) == 0
    rows = {r["grasp_id"]: r for r in read_job(e3m5_job).to_pylist()}
    files = sorted((out / "graspdata").rglob("*.npy"))
    assert len(files) == len(rows) > 0
    hand, model = hands["shadow_e3m5"], peer_model("shadow_e3m5")
    for f in files:
        d = np.load(f, allow_pickle=True).item()
        row = rows[d["grasp_id"]]
        assert f.parent.name == f"scale{round(row['object_scale_m'] * 100):03d}_pose000"
        pieces = sorted((Path(d["obj_path"]) / "urdf" / "meshes").glob("*.obj"))
        ours = (e3m5_job / row["object_path"] / layout.PIECES_DIR).glob("coacd_convex_piece_*")
        assert len(pieces) == len(list(ours))
        for k in POSES:
            err = np.linalg.norm(_peer_tips(model, hand, d[k]) - _our_tips(hand, row[k]), axis=-1).max()
            assert err < TOL_M


@pytest.mark.parametrize("name", HANDS)
def test_tabletop_rows_export_in_the_table_frame(name, hands, tmp_path):
    """A tabletop row goes to the peer in its table frame (its floor z = 0): obj_pose the row's
    object_pose_table, the hand carried with the object, the stable pose in the folder name; the
    import takes it back to our object frame."""
    hand = hands[name]
    _box_entry(tmp_path)
    poses = _random_poses(hand, 2, np.random.default_rng(11))
    q = np.array([0.9, 0.3, -0.2, 0.1])
    T = np.concatenate([[0.02, -0.01, 0.035], q / np.linalg.norm(q)])
    path = _table(tmp_path / "grasps.parquet", name, poses)
    t = pq.read_table(path)
    t = t.append_column("scene", pa.array(["tabletop"] * 2)).append_column("stable_pose", pa.array([1, 1], pa.int32()))
    t = t.append_column("object_pose_table", pa.array([T.tolist()] * 2, pa.list_(pa.float32(), 7)))
    pq.write_table(t, path)
    assert main(["export", str(path), "--format", "dexgraspbench", "--out", str(tmp_path / "dgb")]) == 0
    files = sorted((tmp_path / "dgb" / "graspdata").rglob("*.npy"))
    assert {f.parent.name for f in files} == {"scale008_pose001"}
    from datagen.interop import pose7_to_matrix

    M, model = pose7_to_matrix(T.astype(np.float32).astype(np.float64)), peer_model(name)
    rows = {r["grasp_id"]: r for r in t.to_pylist()}
    for f in files:
        d = np.load(f, allow_pickle=True).item()
        assert np.allclose(d["obj_pose"], T, atol=1e-6)
        ours = _our_tips(hand, rows[d["grasp_id"]]["grasp_qpos"])
        table_frame = ours @ M[:3, :3].T + M[:3, 3]
        assert np.linalg.norm(_peer_tips(model, hand, d["grasp_qpos"]) - table_frame, axis=-1).max() < TOL_M
    back = tmp_path / "back.parquet"
    assert main(["import", "--format", "dexgraspbench", str(files[0].parent), "--hand", name, "--out", str(back)]) == 0
    r = pq.read_table(back).to_pylist()[0]
    ref = rows[np.load(sorted(files[0].parent.glob("*.npy"))[0], allow_pickle=True).item()["grasp_id"]]
    assert np.linalg.norm(_our_tips(hand, r["grasp_qpos"]) - _our_tips(hand, ref["grasp_qpos"]), axis=-1).max() < TOL_M
