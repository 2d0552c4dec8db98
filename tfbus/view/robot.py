"""``tfbus view --urdf PATH``: a robot's link geometry (boxes, cylinders, spheres and
meshes) from its URDF, drawn on each link's frame so it follows the transforms that
``RobotStatePublisher`` (or any broadcaster) sends.

A ``<mesh filename=...>`` is found as rviz's resource retriever finds it:
``package://PKG/REST`` in each ``--mesh-dir`` / ``ROS_PACKAGE_PATH`` entry (``DIR/PKG/REST``,
or ``DIR/REST`` when ``DIR`` is the package itself) and in the folders above the URDF
(``.../PKG/REST``, the usual ``PKG/urdf/robot.urdf`` layout); ``file:///ABS`` as that path; a
bare path relative to the URDF. It is read with trimesh (a dependency of viser: STL, OBJ,
and COLLADA ``.dae`` through pycollada), scaled by the ``scale`` attribute. A mesh that is
not found or cannot be read is not drawn: one line says why (:attr:`RobotModel.notes`).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import unquote, urlparse

import numpy as np
import numpy.typing as npt

from tfbus.geometry import quaternion_from_euler

__all__ = ["LinkVisual", "RobotModel", "link_visuals", "load_robot", "resolve_mesh"]


@dataclass(frozen=True)
class LinkVisual:
    """One ``<visual>`` of a link: ``kind`` is ``"box"`` (``size`` = x, y, z metres),
    ``"cylinder"`` (radius, length; axis z, as URDF), ``"sphere"`` (radius,) or ``"mesh"``
    (``size`` = the x, y, z scale; ``vertices`` ``(V, 3) float32`` metres after scaling and
    ``faces`` ``(F, 3) uint32``); ``xyz``/``wxyz`` its origin in the link frame; ``rgb``
    0-255 (the URDF material's, else the mesh's own colour when it has one, else grey);
    ``source`` the mesh file read."""

    link: str
    kind: str
    size: tuple[float, ...]
    xyz: tuple[float, float, float]
    wxyz: tuple[float, float, float, float]
    rgb: tuple[int, int, int]
    vertices: npt.NDArray[np.float32] | None = field(default=None, compare=False)
    faces: npt.NDArray[np.uint32] | None = field(default=None, compare=False)
    source: Path | None = None


@dataclass(frozen=True)
class RobotModel:
    """What ``--urdf`` draws: the visuals, and one line per visual left out (a mesh not
    found or unreadable)."""

    visuals: tuple[LinkVisual, ...]
    notes: tuple[str, ...] = ()


def _package_dirs(extra: Sequence[Path]) -> list[Path]:
    env = os.environ.get("ROS_PACKAGE_PATH", "")
    return [*extra, *(Path(d) for d in env.split(os.pathsep) if d)]


def resolve_mesh(filename: str, urdf: Path, mesh_dirs: Sequence[Path] = ()) -> tuple[
        Path | None, list[Path]]:
    """Where the mesh ``filename`` of the URDF file ``urdf`` is: ``(path, [])``, or
    ``(None, places looked at)``. ``mesh_dirs`` come before ``ROS_PACKAGE_PATH``'s
    entries (see the module's docstring for the rules)."""
    url = urlparse(filename)
    tried: list[Path] = []
    if url.scheme == "package":
        pkg, rest = url.netloc, unquote(url.path).lstrip("/")
        for d in _package_dirs(mesh_dirs):
            tried.append(d / pkg / rest)
            if d.name == pkg:
                tried.append(d / rest)
        for up in urdf.resolve().parents:
            if up.name == pkg:
                tried.append(up / rest)
    elif url.scheme == "file":
        tried.append(Path(unquote(url.path)))
    elif not url.scheme:
        tried.append(urdf.parent / filename)
    for candidate in tried:
        if candidate.is_file():
            return candidate, []
    return None, tried


def _read_mesh(path: Path, scale: tuple[float, float, float]) -> tuple[
        npt.NDArray[np.float32], npt.NDArray[np.uint32], tuple[int, int, int] | None]:
    """Vertices (scaled), faces and the mesh's main colour (None if it has none).

    Raises:
        ValueError: trimesh cannot read it, or it has no triangles.
    """
    import trimesh

    try:
        mesh: Any = trimesh.load(str(path), force="mesh")
    except Exception as err:  # trimesh raises per format (ValueError, KeyError, ImportError)
        raise ValueError(" ".join(str(err).split()) or type(err).__name__) from None
    faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), dtype=np.uint32)
    if not len(faces):
        raise ValueError("no triangles in it")
    vertices = (np.asarray(mesh.vertices, dtype=np.float64) * np.asarray(scale))
    colour = None
    visual: Any = getattr(mesh, "visual", None)
    if visual is not None and getattr(visual, "kind", None) in ("face", "vertex"):
        main = np.asarray(visual.main_color)[:3]
        colour = (int(main[0]), int(main[1]), int(main[2]))
    return vertices.astype(np.float32), faces, colour


def _colour_of(visual: Any, materials: dict[str, Any]) -> Any:
    mat = getattr(visual, "material", None)
    colour = getattr(mat, "color", None) if mat is not None else None
    if colour is None and mat is not None and getattr(mat, "name", None) in materials:
        colour = getattr(materials[mat.name], "color", None)
    return getattr(colour, "rgba", None) or None


def _rgb(visual: Any, materials: dict[str, Any]) -> tuple[int, int, int]:
    rgba = _colour_of(visual, materials)
    if not rgba:
        return (180, 180, 180)
    r, g, b = (max(0, min(255, round(255 * float(c)))) for c in rgba[:3])
    return (r, g, b)


def link_visuals(path: Path, mesh_dirs: Sequence[Path] = ()) -> list[LinkVisual]:
    """The visuals of every link of a URDF file that can be drawn, in file order
    (:func:`load_robot`'s, without its notes).

    Raises:
        ValueError: the file cannot be read or parsed (the message says why).
    """
    return list(load_robot(path, mesh_dirs).visuals)


def load_robot(path: Path, mesh_dirs: Sequence[Path] = ()) -> RobotModel:
    """The box, cylinder, sphere and mesh visuals of every link of a URDF file (read with
    ROS's ``urdf_parser_py``, the ``tfbus[robot]`` extra), in file order; each mesh that
    is not found (:func:`resolve_mesh`) or cannot be read is a note instead.

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
    notes: list[str] = []
    for link in robot.links:
        for v in link.visuals or []:
            g = v.geometry
            kind = type(g).__name__
            mesh: tuple[Any, ...] = (None, None, None, None)
            size: tuple[float, ...]
            if kind == "Mesh":
                filename = str(getattr(g, "filename", "") or "")
                found, tried = resolve_mesh(filename, path, mesh_dirs)
                if found is None:
                    where = (f"looked in {', '.join(map(str, tried))}" if tried else
                             "no --mesh-dir, ROS_PACKAGE_PATH folder or folder named "
                             f"{urlparse(filename).netloc or '?'} above the URDF to look in")
                    notes.append(f"{link.name}: mesh {filename} not found ({where}"
                                 f"{'; --mesh-dir' if tried else ''})")
                    continue
                raw = getattr(g, "scale", None) or (1.0, 1.0, 1.0)
                scale = tuple(float(c) for c in raw)
                size = scale if len(scale) == 3 else (1.0, 1.0, 1.0)
                try:
                    vertices, faces, own = _read_mesh(found, (size[0], size[1], size[2]))
                except ValueError as err:
                    notes.append(f"{link.name}: mesh {found} cannot be read: {err}")
                    continue
                mesh = (vertices, faces, own, found)
            elif kind == "Box":
                size = tuple(float(s) for s in g.size)
            elif kind == "Cylinder":
                size = (float(g.radius), float(g.length))
            elif kind == "Sphere":
                size = (float(g.radius),)
            elif kind != "Mesh":
                continue
            origin = getattr(v, "origin", None)
            xyz = tuple(float(c) for c in (origin.xyz if origin is not None and origin.xyz
                                           else (0.0, 0.0, 0.0)))
            rpy = origin.rpy if origin is not None and origin.rpy else (0.0, 0.0, 0.0)
            q = quaternion_from_euler(float(rpy[0]), float(rpy[1]), float(rpy[2]))
            rgb = _rgb(v, materials)
            if kind == "Mesh" and _colour_of(v, materials) is None and mesh[2] is not None:
                rgb = mesh[2]
            out.append(LinkVisual(
                link=link.name, kind=kind.lower(), size=size,
                xyz=(xyz[0], xyz[1], xyz[2]),
                wxyz=(float(q[3]), float(q[0]), float(q[1]), float(q[2])),
                rgb=rgb, vertices=mesh[0], faces=mesh[1],
                source=mesh[3] if kind == "Mesh" else None))
    return RobotModel(tuple(out), tuple(notes))
