"""``tfbus view --urdf PATH``: a robot's link geometry (boxes, cylinders, spheres) from its
URDF, drawn on each link's frame so it follows the transforms that
``RobotStatePublisher`` (or any broadcaster) sends. Meshes are not drawn (yet)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tfbus.geometry import quaternion_from_euler

__all__ = ["LinkVisual", "link_visuals"]


@dataclass(frozen=True)
class LinkVisual:
    """One ``<visual>`` of a link: ``kind`` is ``"box"`` (``size`` = x, y, z metres),
    ``"cylinder"`` (radius, length; axis z, as URDF) or ``"sphere"`` (radius,);
    ``xyz``/``wxyz`` its origin in the link frame; ``rgb`` 0-255."""

    link: str
    kind: str
    size: tuple[float, ...]
    xyz: tuple[float, float, float]
    wxyz: tuple[float, float, float, float]
    rgb: tuple[int, int, int]


def _rgb(visual: Any, materials: dict[str, Any]) -> tuple[int, int, int]:
    mat = getattr(visual, "material", None)
    colour = getattr(mat, "color", None) if mat is not None else None
    if colour is None and mat is not None and getattr(mat, "name", None) in materials:
        colour = getattr(materials[mat.name], "color", None)
    rgba = getattr(colour, "rgba", None)
    if not rgba:
        return (180, 180, 180)
    r, g, b = (max(0, min(255, round(255 * float(c)))) for c in rgba[:3])
    return (r, g, b)


def link_visuals(path: Path) -> list[LinkVisual]:
    """The box, cylinder and sphere visuals of every link of a URDF file (read with ROS's
    ``urdf_parser_py``, the ``tfbus[robot]`` extra), in file order; meshes are skipped.

    Raises:
        ValueError: the file cannot be read or parsed (the message says why).
    """
    from urdf_parser_py import urdf

    try:
        robot = urdf.URDF.from_xml_string(path.read_text(encoding="utf-8"))
    except Exception as err:  # urdf_parser_py raises what lxml and its checks raise
        raise ValueError(f"--urdf {str(path)!r}: {' '.join(str(err).split())}") from None
    materials = {m.name: m for m in (robot.materials or []) if getattr(m, "name", None)}
    out: list[LinkVisual] = []
    for link in robot.links:
        for v in link.visuals or []:
            g = v.geometry
            kind = type(g).__name__
            if kind == "Box":
                size: tuple[float, ...] = tuple(float(s) for s in g.size)
            elif kind == "Cylinder":
                size = (float(g.radius), float(g.length))
            elif kind == "Sphere":
                size = (float(g.radius),)
            else:
                continue
            origin = getattr(v, "origin", None)
            xyz = tuple(float(c) for c in (origin.xyz if origin is not None and origin.xyz
                                           else (0.0, 0.0, 0.0)))
            rpy = origin.rpy if origin is not None and origin.rpy else (0.0, 0.0, 0.0)
            q = quaternion_from_euler(float(rpy[0]), float(rpy[1]), float(rpy[2]))
            out.append(LinkVisual(
                link=link.name, kind=kind.lower(), size=size,
                xyz=(xyz[0], xyz[1], xyz[2]),
                wxyz=(float(q[3]), float(q[0]), float(q[1]), float(q[2])),
                rgb=_rgb(v, materials)))
    return out
