"""MuJoCo model (MJCF) of an object's convex pieces: one free body, total mass fixed.

The pieces are stored in normalized units; the model applies the object scale (metres per
normalized unit) through each mesh asset's ``scale``. Each piece's mass is the total mass times
its volume fraction (volume fractions do not depend on the scale); MuJoCo derives inertia from
the piece shapes.
"""

from __future__ import annotations

from pathlib import Path
from xml.sax.saxutils import quoteattr

__all__ = ["object_mjcf", "check_mjcf"]


def object_mjcf(piece_files: list[str], volumes: list[float], scale: float, *,
                meshdir: str, total_mass_kg: float = 0.1, condim: int = 4,
                friction: tuple = (0.6, 0.02, 0.0001), name: str = "object") -> str:
    """MJCF text of a free body made of mesh geoms.

    piece_files: file names relative to ``meshdir``; volumes: (P,) piece volumes, any unit;
    scale: metres per normalized unit (the manifest scale); meshdir: directory of the pieces
    (absolute, or relative to the XML file's directory).
    """
    if len(piece_files) != len(volumes) or not piece_files:
        raise ValueError(f"MJCF of {name!r}: need one volume per piece, got "
                         f"{len(piece_files)} files and {len(volumes)} volumes")
    if scale <= 0 or total_mass_kg <= 0:
        raise ValueError(f"MJCF of {name!r}: scale and total mass must be > 0")
    total = float(sum(volumes))
    s = f"{scale:.9g}"
    fr = " ".join(f"{x:.9g}" for x in friction)
    assets, geoms = [], []
    for i, (fname, vol) in enumerate(zip(piece_files, volumes)):
        assets.append(f'    <mesh name="{name}_piece_{i}" file={quoteattr(fname)} '
                      f'scale="{s} {s} {s}" inertia="convex"/>')
        geoms.append(f'      <geom name="{name}_geom_{i}" type="mesh" mesh="{name}_piece_{i}" '
                     f'mass="{total_mass_kg * vol / total:.9g}" condim="{condim}" friction="{fr}"/>')
    return "\n".join([
        f'<mujoco model={quoteattr(name)}>',
        f'  <compiler angle="radian" meshdir={quoteattr(meshdir)}/>',
        "  <asset>", *assets, "  </asset>",
        "  <worldbody>",
        f'    <body name={quoteattr(name)}>',
        f'      <freejoint name="{name}_root"/>',
        *geoms,
        "    </body>",
        "  </worldbody>",
        "</mujoco>",
    ]) + "\n"


def check_mjcf(xml_path: str | Path) -> float:
    """Compile the model with MuJoCo; return the body mass (kg). Raises ValueError on failure."""
    import mujoco

    try:
        model = mujoco.MjModel.from_xml_path(str(xml_path))
    except Exception as exc:
        raise ValueError(f"MuJoCo rejected {xml_path}: {exc}") from exc
    return float(model.body_mass[1:].sum())
