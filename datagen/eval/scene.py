"""The evaluation scene: a hand and an object's convex pieces in one MuJoCo model (via MjSpec).

World frame = object frame. The hand's flattened MJCF (``HandModel.mjcf_path``) is attached
under ``hand_base``, a body with a free joint welded to the mocap body ``hand_mocap``; the hand
is driven by moving the mocap body and by its position actuators (gains set from the config).
The object is one body of the convex pieces at ``scale`` metres per normalized unit, total
mass ``EvalConfig.object_mass_kg`` split by piece volume, on a free joint or on the virtual
hinge/slide joint of a task (with its end stops, if it has any). Every geom gets the config's
condim, friction and margin; hand geoms get the hand solimp/solref; the hand's position actuators
get the gains of ``EvalConfig.protocol`` (`datagen.eval.protocol`). A task test's scenery (static
boxes round a mounted part: door, panel, housing, cabinet) is a static body ``scenery``; its
contacts with the object are excluded (the part moves inside it), the hand collides with it.
A tabletop row's table (its ``support_plane`` ``[n, d]`` in the object frame,
`datagen.objects.tabletop`) is a static plane geom ``table_geom`` through ``-d n`` facing ``n``
in body ``table``: the object rests on it, the hand collides with it (`datagen.eval.lift`).

Rooting (``EvalConfig.hand_root``): ``"spec"`` attaches the hand from its spec's root body (for
the Shadow hands: the forearm, its 3-4 kg driven through the two wrist joints by the actuators).
``"palm"`` attaches only the palm (the lowest common ancestor of the fingertip links) and what
hangs from it, the way the peer benchmark roots the hand: the joints between the root and the
palm (the wrist) are held at the row's values, i.e. the mocap target is the palm's pose computed
from the row's root pose and wrist angles (``Scene.root_target``, MuJoCo's own kinematics of the
hand MJCF); the forearm's geoms and the wrist actuators are not in the scene.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np

from .config import EvalConfig, EvalError, TaskTest
from .protocol import hand_gains

__all__ = ["ObjectPieces", "Scene", "build_scene", "pieces_from_processed", "HAND_PREFIX"]

HAND_PREFIX = "hand/"
_INTEGRATORS = {"euler": mujoco.mjtIntegrator.mjINT_EULER, "rk4": mujoco.mjtIntegrator.mjINT_RK4,
                "implicit": mujoco.mjtIntegrator.mjINT_IMPLICIT,
                "implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST}
_NO_STOP = 1e3  # m or rad: the range bound of a joint side without an end stop
_CONES = {"pyramidal": mujoco.mjtCone.mjCONE_PYRAMIDAL, "elliptic": mujoco.mjtCone.mjCONE_ELLIPTIC}


@dataclass(frozen=True)
class ObjectPieces:
    """An object as convex mesh pieces in normalized units (files MuJoCo can read: OBJ/STL).

    ``volumes`` (P,) any common unit, only their ratios matter (the mass split); ``scale`` is
    metres per normalized unit (the manifest's object scale)."""

    object_id: str
    paths: tuple[Path, ...]
    volumes: tuple[float, ...]
    scale: float

    def __post_init__(self) -> None:
        paths = tuple(Path(p) for p in self.paths)
        object.__setattr__(self, "paths", paths)
        object.__setattr__(self, "volumes", tuple(float(v) for v in self.volumes))
        if not paths or len(paths) != len(self.volumes):
            raise EvalError(f"object {self.object_id!r}", f"needs one volume per piece ({len(paths)} pieces, "
                            f"{len(self.volumes)} volumes)")
        if not all(v > 0 for v in self.volumes) or not self.scale > 0:
            raise EvalError(f"object {self.object_id!r}", "piece volumes and the scale must be > 0")
        missing = [str(p) for p in paths if not p.is_file()]
        if missing:
            raise EvalError(f"object {self.object_id!r}", f"piece files not found: {missing[:3]}",
                            "re-run `datagen prepare` or fix object_path")


def pieces_from_processed(processed, scale: float) -> ObjectPieces:
    """`ObjectPieces` of a `datagen.objects.ProcessedObject` (status ok) at ``scale`` metres."""
    if not processed.ok:
        raise EvalError(f"object {processed.object_id!r}", f"processing failed ({processed.reason})",
                        "evaluate grasps of successfully processed objects only")
    return ObjectPieces(processed.object_id, tuple(processed.piece_paths), tuple(processed.piece_volumes),
                        float(scale))


@dataclass
class Scene:
    """A compiled scene and the indices evaluation needs (see the module docstring).

    Shapes: J hand joints (in ``hand.joint_names`` order), nu actuators, G hand collision
    geoms, P object geoms."""

    model: mujoco.MjModel
    hand: object                     # datagen.hands.HandModel
    objects: ObjectPieces
    joint: str                       # "free", "hinge" or "slide"
    hand_qpos_adr: np.ndarray        # (J,) qpos address of each hand joint
    hand_free_qpos: int              # qpos address of the hand root's free joint (7 values)
    hand_free_dof: int               # dof address of the hand root's free joint (6 values)
    object_qpos: int                 # qpos address of the object's joint
    object_dof: int
    object_body: int
    mocap: int                       # mocap index of hand_mocap
    actuators: np.ndarray            # (nu,) scene actuator ids in the hand's actuator order
    ctrl_matrix: np.ndarray          # (nu, J) ctrl = A @ joints
    ctrl_range: np.ndarray           # (nu, 2)
    hand_geoms: np.ndarray           # (G,) hand collision geom ids
    hand_geom_link: np.ndarray       # (G,) index into hand.link_names of each hand geom's body
    object_geoms: np.ndarray         # (P,) object geom ids
    scenery_geoms: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # (E,) static scenery geom ids
    table_geoms: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # (0 or 1,) the table's plane geom
    self_pairs: np.ndarray | None = None  # (S, 2) hand geom pairs of the self-penetration metric (lazy)
    # hand_root "palm": the joints of the row the scene simulates (J',) (None: all J), and the
    # kinematics of the palm relative to the row's root (see ``root_target``)
    sim_joints: np.ndarray | None = None
    palm_kinematics: "_PalmKinematics | None" = field(default=None, repr=False)

    @property
    def object_mass(self) -> float:
        return float(self.model.body_subtreemass[self.object_body])

    def hand_joints(self, joints: np.ndarray) -> np.ndarray:
        """(J',) the values of the simulated joints among a row's joints (J,)."""
        return joints if self.sim_joints is None else joints[self.sim_joints]

    def root_target(self, pos: np.ndarray, quat: np.ndarray, joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pose (3,), (4,) [w x y z] of the scene's hand base (welded to the mocap body) for a
        row's root pose and joints (J,): the row's root itself, or for ``hand_root: palm`` the
        palm's pose with the wrist joints at the row's values."""
        if self.palm_kinematics is None:
            return pos, quat
        return self.palm_kinematics.palm_pose(pos, quat, joints)

    def ctrl(self, joints: np.ndarray) -> np.ndarray:
        """(nu,) actuator targets for joints (J,) radians, clipped to the control range."""
        return np.clip(self.ctrl_matrix @ joints, self.ctrl_range[:, 0], self.ctrl_range[:, 1])


def _set_contact(geom, cfg: EvalConfig, hand: bool) -> None:
    geom.condim = cfg.condim
    geom.friction = [cfg.friction[0], cfg.friction[1], 1e-4]
    geom.margin = cfg.geom_margin_m
    geom.gap = 0.0
    if hand:
        geom.solimp[:3] = cfg.hand_solimp
        geom.solref = list(cfg.hand_solref)


def build_scene(hand, pieces: ObjectPieces, cfg: EvalConfig, task: TaskTest | None = None,
                table=None, *, visual: bool = True) -> Scene:
    """Compile the scene of ``hand`` (a `HandModel`) and ``pieces``; ``task`` selects the
    object's joint (None: free); ``table`` (4,) ``[n, d]``: the support plane of a tabletop row
    (None: no table). ``visual`` False leaves out the hand's visual geoms (neither contype nor
    conaffinity) of bodies with an explicit inertial, where they change no mass, and the meshes
    only they use: the same dynamics (benchmarks/results/eval.md), without compiling LEAP's
    120k-vertex visual meshes in every scene (the evaluator's scenes; a render keeps them).
    Raises `EvalError` if MuJoCo rejects the model."""
    spec = mujoco.MjSpec()
    _set_options(spec.option, cfg)
    spec.compiler.degree = False
    palm = _attach_hand(spec, hand, cfg, visual)
    _set_hand_physics(spec, hand, cfg)
    body = _add_object_body(spec, task)
    if task is not None and task.scenery:
        _add_scenery(spec, task.scenery, cfg)
    if table is not None:
        _add_table(spec, np.asarray(table, dtype=np.float64), cfg)
    _add_object_pieces(spec, body, pieces, cfg)
    spec.worldbody.add_light(pos=[0, 0, 1.5], dir=[0, 0, -1], type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL,
                             castshadow=False)
    try:
        model = spec.compile()
    except Exception as exc:
        raise EvalError(f"scene of hand {hand.name!r} and object {pieces.object_id!r}",
                        f"MuJoCo cannot compile it: {str(exc).strip()}") from None
    return _index(model, hand, pieces, "free" if task is None else task.joint, palm)


def _set_options(opt, cfg: EvalConfig) -> None:
    """The scene's solver options from the protocol (``opt``: an MjSpec's option)."""
    opt.timestep = cfg.timestep_s
    opt.gravity = list(cfg.gravity)
    opt.integrator = _INTEGRATORS[cfg.integrator]
    opt.cone = _CONES[cfg.cone]
    opt.impratio = cfg.impratio
    opt.noslip_iterations = cfg.noslip_iterations
    if not cfg.multiccd:  # MuJoCo 4 has it on by default, DexGraspBench's 3.3.2 off (EvalConfig)
        opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_MULTICCD)
    if not cfg.island:
        opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_ISLAND)


def _attach_hand(spec: mujoco.MjSpec, hand, cfg: EvalConfig, visual: bool = True) -> "_PalmKinematics | None":
    """The hand under a free ``hand_base`` body welded to the ``hand_mocap`` body: the whole hand
    (``hand_root`` spec) or the palm's subtree without the wrist joints and their actuators,
    tendons and sensors (``hand_root`` palm; returned, None for the whole hand). ``visual``:
    see `build_scene`."""
    hand_spec = mujoco.MjSpec.from_file(str(hand.mjcf_path))
    if not visual:
        _drop_visuals(hand_spec)
    palm = _PalmKinematics(hand) if cfg.hand_root == "palm" else None
    if palm is not None and palm.palm == hand.spec.root_body:
        palm = None  # rooted at the palm already (no wrist): the same scene as hand_root spec
    base = spec.worldbody.add_body(name="hand_base")
    base.add_freejoint(name="hand_free")
    # the scene keeps its own solver options and sizes; the hand's user-field sizes are adopted
    for k in ("timestep", "gravity", "integrator", "cone", "impratio", "noslip_iterations", "iterations",
              "tolerance", "ls_iterations", "solver", "jacobian", "disableflags", "enableflags"):
        setattr(hand_spec.option, k, getattr(spec.option, k))
    hand_spec.njmax, hand_spec.nconmax = spec.njmax, spec.nconmax
    for k in ("nuser_jnt", "nuser_site", "nuser_tendon", "nuser_actuator", "nuser_sensor", "nuser_body",
              "nuser_geom", "nuser_cam"):
        setattr(spec, k, getattr(hand_spec, k))
    if palm is None:
        base.add_frame().attach_body(hand_spec.body(hand.spec.root_body), HAND_PREFIX, "")
    else:  # the palm's subtree, its frame at the hand base; the wrist joints and actuators dropped
        body = base.add_frame().attach_body(hand_spec.body(palm.palm), HAND_PREFIX, "")
        body.pos, body.quat = [0, 0, 0], [1, 0, 0, 0]
        _drop_wrist(spec, body, palm)
    spec.worldbody.add_body(name="hand_mocap", mocap=True)
    weld = spec.add_equality(type=mujoco.mjtEq.mjEQ_WELD, objtype=mujoco.mjtObj.mjOBJ_BODY,
                             name1="hand_mocap", name2="hand_base")
    # data = anchor (3), relpose pos (3) and quat (4), torquescale, flag (0: relpose as given)
    weld.data[:12] = [0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 1, 0]
    weld.solref = list(cfg.weld_solref)
    return palm


def _drop_visuals(spec: mujoco.MjSpec) -> None:
    """Delete the visual geoms (no contype, no conaffinity, in no explicit contact pair) of bodies
    with an explicit inertial (their mass and inertia are the inertial's, not the geoms') and the
    meshes no geom uses then."""
    paired = {n for p in spec.pairs for n in (p.geomname1, p.geomname2)}
    for g in [g for g in spec.geoms if not (g.contype or g.conaffinity) and g.parent.explicitinertial
              and g.name not in paired]:
        spec.delete(g)
    used = {g.meshname for g in spec.geoms if g.type == mujoco.mjtGeom.mjGEOM_MESH}
    for m in [m for m in spec.meshes if m.name not in used]:
        spec.delete(m)


def _drop_wrist(spec: mujoco.MjSpec, body, palm: "_PalmKinematics") -> None:
    """Delete the palm body's own joints and the actuators, tendons and sensors of the held wrist."""
    held = {HAND_PREFIX + n for n in palm.held_names}
    for j in list(body.joints):
        spec.delete(j)
    held |= {HAND_PREFIX + n for n in palm.held_tendons}
    for a in [a for a in spec.actuators if a.target in held]:
        spec.delete(a)
    for t in [t for t in spec.tendons if t.name in held]:
        spec.delete(t)
    for x in [x for x in spec.sensors if x.objname in held]:
        spec.delete(x)


def _set_hand_physics(spec: mujoco.MjSpec, hand, cfg: EvalConfig) -> None:
    """The protocol's joint friction, contact parameters (geoms and explicit self-collision
    pairs) and position-actuator gains on the hand (the only bodies in ``spec`` so far)."""
    if cfg.joint_frictionloss is not None:  # the hand's joints (the object's are added later)
        for j in spec.joints:
            if j.type != mujoco.mjtJoint.mjJNT_FREE:
                j.frictionloss = cfg.joint_frictionloss
    for g in spec.geoms:
        _set_contact(g, cfg, hand=True)
    for p in spec.pairs:  # explicit self-collision pairs of the hand MJCF
        p.condim = cfg.condim
        p.friction = [cfg.friction[0], cfg.friction[0], cfg.friction[1], 1e-4, 1e-4]
        p.solimp[:3] = cfg.hand_solimp
        p.solref = list(cfg.hand_solref)
        p.margin = cfg.geom_margin_m
    for a in spec.actuators:
        # the protocol's gains (datagen/eval/protocol.py): DexGraspBench's hand files, or the
        # config's kp and force limit for every hand with the asset's kv capped at kp times the
        # config's time constant (a large kv at kp 5 would close a finger after the 0.4 s phases)
        g = hand_gains(cfg, hand.name, -float(a.biasprm[2]))
        a.gainprm[0] = g.kp
        a.biasprm[1] = -g.kp
        a.biasprm[2] = -g.kv
        a.forcelimited = mujoco.mjtLimited.mjLIMITED_FALSE if g.force_limit is None else mujoco.mjtLimited.mjLIMITED_TRUE
        if g.force_limit is not None:
            a.forcerange = [-g.force_limit, g.force_limit]


def _add_object_body(spec: mujoco.MjSpec, task: TaskTest | None):
    """The ``object`` body with its joint: free, or the task's hinge / slide (and its stops)."""
    body = spec.worldbody.add_body(name="object")
    if task is None or task.joint == "free":
        body.add_freejoint(name="object_joint")
        return body
    kind = mujoco.mjtJoint.mjJNT_HINGE if task.joint == "hinge" else mujoco.mjtJoint.mjJNT_SLIDE
    j = body.add_joint(name="object_joint", type=kind, axis=list(task.axis), pos=list(task.anchor),
                       damping=0.0, armature=0.0)
    if task.limits is not None:  # a free side: a stop far beyond any pass threshold
        j.limited = mujoco.mjtLimited.mjLIMITED_TRUE
        j.range = [-_NO_STOP if task.limits[0] is None else task.limits[0],
                   _NO_STOP if task.limits[1] is None else task.limits[1]]
    return body


def _add_scenery(spec: mujoco.MjSpec, scenery, cfg: EvalConfig) -> None:
    """Static boxes ``[(lo (3,), hi (3,)), ...]`` m round a mounted part: they stop the hand, not
    the part (it moves inside them)."""
    env = spec.worldbody.add_body(name="scenery")
    for i, (lo, hi) in enumerate(scenery):
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        g = env.add_geom(name=f"scenery_geom_{i}", type=mujoco.mjtGeom.mjGEOM_BOX, pos=list((lo + hi) / 2),
                         size=list((hi - lo) / 2), rgba=[0.6, 0.6, 0.65, 0.5])
        _set_contact(g, cfg, hand=False)
    spec.add_exclude(bodyname1="object", bodyname2="scenery")


def _add_object_pieces(spec: mujoco.MjSpec, body, pieces: ObjectPieces, cfg: EvalConfig) -> None:
    """The object's convex pieces as mesh geoms, the protocol's mass shared by volume."""
    total = sum(pieces.volumes)
    s = pieces.scale
    for i, (path, vol) in enumerate(zip(pieces.paths, pieces.volumes)):
        spec.add_mesh(name=f"object_piece_{i}", file=str(path.resolve()), scale=[s, s, s],
                      inertia=mujoco.mjtMeshInertia.mjMESH_INERTIA_CONVEX)
        g = body.add_geom(name=f"object_geom_{i}", type=mujoco.mjtGeom.mjGEOM_MESH,
                          meshname=f"object_piece_{i}", mass=cfg.object_mass_kg * vol / total,
                          rgba=[0.85, 0.55, 0.2, 1.0])
        _set_contact(g, cfg, hand=False)


def _add_table(spec: mujoco.MjSpec, plane: np.ndarray, cfg: EvalConfig) -> None:
    """The table: a plane geom through ``-d n`` with its normal along ``n`` (plane ``[n, d]``)."""
    n = plane[:3] / np.linalg.norm(plane[:3])
    quat = np.zeros(4)
    mujoco.mju_quatZ2Vec(quat, n)
    body = spec.worldbody.add_body(name="table")
    g = body.add_geom(name="table_geom", type=mujoco.mjtGeom.mjGEOM_PLANE, pos=list(-plane[3] * n), quat=list(quat),
                      size=[0.25, 0.25, 0.01], rgba=[0.55, 0.45, 0.35, 1.0])
    _set_contact(g, cfg, hand=False)


class _PalmKinematics:
    """The palm's pose relative to the hand's root for given wrist angles (hand_root: palm).

    ``palm``: the lowest common ancestor of the fingertip links; ``held_names``: the joints on
    the path from the root body to the palm (the palm's own included). Uses MuJoCo's kinematics
    of the hand MJCF alone (``mj_kinematics``)."""

    def __init__(self, hand) -> None:
        self.model = mujoco.MjModel.from_xml_path(str(hand.mjcf_path))
        self.data = mujoco.MjData(self.model)
        m = self.model

        def chain(b: int) -> list[int]:
            out = [b]
            while b != 0:
                b = int(m.body_parentid[b])
                out.append(b)
            return out[::-1]

        tips = [chain(m.body(t.link).id) for t in hand.spec.fingertips.values()]
        lca = 0
        for level in zip(*tips):
            if len(set(level)) != 1:
                break
            lca = level[0]
        root = m.body(hand.spec.root_body).id
        path = chain(lca)
        if root not in path:
            raise EvalError(f"hand {hand.name!r}", "hand_root: palm needs the palm below the root body")
        path = path[path.index(root):]
        self.palm = m.body(lca).name
        self.parent = int(m.body_parentid[root])
        held = [j for b in path for j in range(m.body_jntadr[b], m.body_jntadr[b] + m.body_jntnum[b])]
        if any(int(m.jnt_type[j]) not in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)) for j in held):
            raise EvalError(f"hand {hand.name!r}", "hand_root: palm handles hinge and slide wrist joints only")
        self.held_names = [m.joint(j).name for j in held]
        wraps = [(t, m.wrap_objid[w]) for t in range(m.ntendon)
                 for w in range(m.tendon_adr[t], m.tendon_adr[t] + m.tendon_num[t])
                 if int(m.wrap_type[w]) == int(mujoco.mjtWrap.mjWRAP_JOINT)]
        self.held_tendons = sorted({m.tendon(t).name for t, j in wraps if j in held})
        index = {n: i for i, n in enumerate(hand.joint_names)}
        self.held_index = np.array([index[n] for n in self.held_names], dtype=np.int64)
        self.held_qadr = np.array([m.jnt_qposadr[j] for j in held], dtype=np.int64)
        self.lca = lca

    def palm_pose(self, pos: np.ndarray, quat: np.ndarray, joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World pose of the palm for the root at (pos, quat [w x y z]) and joints (J,)."""
        m, d = self.model, self.data
        d.qpos[:] = m.qpos0
        d.qpos[self.held_qadr] = np.asarray(joints)[self.held_index]
        mujoco.mj_kinematics(m, d)
        # the palm in the frame of the root body's parent (which the scene puts at the row's root)
        pq = np.empty(4)
        mujoco.mju_negQuat(pq, d.xquat[self.parent])
        rel_p = np.empty(3)
        mujoco.mju_rotVecQuat(rel_p, d.xpos[self.lca] - d.xpos[self.parent], pq)
        rel_q = np.empty(4)
        mujoco.mju_mulQuat(rel_q, pq, d.xquat[self.lca])
        q = np.asarray(quat, dtype=np.float64)
        q = q / np.linalg.norm(q)
        out_p = np.empty(3)
        mujoco.mju_rotVecQuat(out_p, rel_p, q)
        out_q = np.empty(4)
        mujoco.mju_mulQuat(out_q, q, rel_q)
        return np.asarray(pos, dtype=np.float64) + out_p, out_q


def _index(model: mujoco.MjModel, hand, pieces: ObjectPieces, joint: str, palm: _PalmKinematics | None = None) -> Scene:
    J = hand.num_joints
    held = set() if palm is None else set(palm.held_names)
    sim = np.array([j for j, n in enumerate(hand.joint_names) if n not in held], dtype=np.int64)
    qadr = np.array([model.jnt_qposadr[model.joint(HAND_PREFIX + hand.joint_names[j]).id] for j in sim])
    free = model.joint("hand_free").id
    oj = model.joint("object_joint").id
    names = [n for n in hand.actuator_names if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, HAND_PREFIX + n) >= 0]
    kept = np.array([i for i, n in enumerate(hand.actuator_names) if n in set(names)], dtype=np.int64)
    acts = np.array([model.actuator(HAND_PREFIX + n).id for n in names], dtype=np.int64)
    link_index = {HAND_PREFIX + n: i for i, n in enumerate(hand.link_names)}
    hand_geoms, hand_link = [], []
    obody = model.body("object").id
    for g in range(model.ngeom):
        b = model.body(model.geom_bodyid[g]).name
        if b in link_index and (model.geom_contype[g] or model.geom_conaffinity[g]):
            hand_geoms.append(g)
            hand_link.append(link_index[b])
    obj_geoms = np.array([g for g in range(model.ngeom) if model.geom_bodyid[g] == obody])
    env = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "scenery")
    env_geoms = np.array([g for g in range(model.ngeom) if env >= 0 and model.geom_bodyid[g] == env], dtype=np.int64)
    tb = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "table")
    table_geoms = np.array([g for g in range(model.ngeom) if tb >= 0 and model.geom_bodyid[g] == tb], dtype=np.int64)
    A = hand.ctrl_matrix.detach().cpu().double().numpy()[kept]
    if palm is not None and np.any(A[:, palm.held_index]):
        raise EvalError(f"hand {hand.name!r}", "an actuator couples a wrist joint to a finger; hand_root: palm cannot hold it")
    if A.shape != (len(acts), J):
        raise EvalError(f"hand {hand.name!r}", f"control matrix {A.shape} does not match {len(acts)} actuators")
    return Scene(model=model, hand=hand, objects=pieces, joint=joint, hand_qpos_adr=qadr,
                 hand_free_qpos=int(model.jnt_qposadr[free]), hand_free_dof=int(model.jnt_dofadr[free]),
                 object_qpos=int(model.jnt_qposadr[oj]), object_dof=int(model.jnt_dofadr[oj]),
                 object_body=obody, mocap=int(model.body_mocapid[model.body("hand_mocap").id]),
                 actuators=acts, ctrl_matrix=A, ctrl_range=model.actuator_ctrlrange[acts].copy(),
                 hand_geoms=np.array(hand_geoms), hand_geom_link=np.array(hand_link), object_geoms=obj_geoms,
                 scenery_geoms=env_geoms, table_geoms=table_geoms,
                 sim_joints=None if palm is None else sim, palm_kinematics=palm)
