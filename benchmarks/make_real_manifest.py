"""Write ``manifests/real_dev.jsonl``: the real-object development set of ``make bench-quality``.

Household meshes that registry packages carry (never copied into the repository; ``make
real-objects`` installs them): pybullet's ``pybullet_data`` and metaworld's object meshes. Each
line is a manifest entry of a ``pkg:`` source, so the file works wherever the packages are
installed; ``sha256`` pins the bytes. Scales are the defaults (0.06, 0.08) plus 0.10.
Usage: ``python -m benchmarks.make_real_manifest``.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from datagen.objects.sources import resolve

OUT = Path(__file__).resolve().parents[1] / "manifests" / "real_dev.jsonl"
PYBULLET = "pkg:pybullet_data"
METAWORLD = "pkg:metaworld/assets/objects/meshes"
#: (source, path, family): toys, kitchenware and tools; no object of the procedural families
OBJECTS = [
    (PYBULLET, "duck.obj", "toy"), (PYBULLET, "bunny.obj", "toy"), (PYBULLET, "objects/mug.obj", "kitchen"),
    (PYBULLET, "soccerball.obj", "ball"), (PYBULLET, "stone.obj", "rock"), (PYBULLET, "lego/lego.obj", "toy"),
    (PYBULLET, "jenga/jenga.obj", "block"),
    (METAWORLD, "coffeemachine/mug.stl", "kitchen"), (METAWORLD, "coffeemachine/cup.stl", "kitchen"),
    (METAWORLD, "thermos/therm_body.stl", "kitchen"), (METAWORLD, "puck/puck.stl", "disc"),
    (METAWORLD, "plug/plug.stl", "tool"), (METAWORLD, "dial/dial.stl", "disc"),
    (METAWORLD, "hammer/hammerhead.stl", "tool"),
]
SCALES = (0.06, 0.08, 0.10)


def main() -> None:
    lines = []
    for source, path, family in OBJECTS:
        name = path.replace("/", "__").rsplit(".", 1)[0]
        oid = f"{source.split(':')[1].split('/')[0]}__{name}"
        data = resolve(source, path, oid).read_bytes()
        lines.append(json.dumps({"id": oid, "source": source, "path": path, "family": family,
                                 "sha256": hashlib.sha256(data).hexdigest(), "scales": list(SCALES),
                                 "split": "test"}, sort_keys=True))
    OUT.write_text("\n".join(lines) + "\n")
    print(f"wrote {OUT}: {len(lines)} objects")


if __name__ == "__main__":
    main()
