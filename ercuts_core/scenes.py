"""Built-in scenes as plain descriptions: the S-corridor of the paper's Fig. 1, a Cornell box,
and analytic furnace scenes. Used by the command line, the tests and the benchmarks.
"""
from __future__ import annotations

import numpy as np

from .description import (AreaLights, CameraDesc, MaterialTable, MeshTable, PointLights,
                          SceneDescription)


class _Builder:
    """Accumulates quads/triangles per object and material."""

    def __init__(self):
        self.pos: list[np.ndarray] = []
        self.tris: list[np.ndarray] = []
        self.mat: list[int] = []
        self.obj: list[int] = []
        self.names: list[str] = []
        self.n = 0

    def object(self, name: str) -> int:
        self.names.append(name)
        return len(self.names) - 1

    def quad(self, p0, p1, p2, p3, mat: int, obj: int) -> None:
        """Counter-clockwise quad p0 p1 p2 p3 (normal by the right-hand rule)."""
        self.pos.append(np.array([p0, p1, p2, p3], np.float64))
        self.tris.append(np.array([[0, 1, 2], [0, 2, 3]]) + self.n)
        self.mat += [mat, mat]
        self.obj += [obj, obj]
        self.n += 4

    def box(self, lo, hi, mat: int, obj: int, inward: bool = False) -> None:
        """Axis-aligned box with outward (or inward) faces."""
        x0, y0, z0 = lo
        x1, y1, z1 = hi
        faces = [
            [(x0, y0, z0), (x0, y0, z1), (x0, y1, z1), (x0, y1, z0)],  # -x
            [(x1, y0, z0), (x1, y1, z0), (x1, y1, z1), (x1, y0, z1)],  # +x
            [(x0, y0, z0), (x1, y0, z0), (x1, y0, z1), (x0, y0, z1)],  # -y
            [(x0, y1, z0), (x0, y1, z1), (x1, y1, z1), (x1, y1, z0)],  # +y
            [(x0, y0, z0), (x0, y1, z0), (x1, y1, z0), (x1, y0, z0)],  # -z
            [(x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)],  # +z
        ]
        for f in faces:
            self.quad(*(f[::-1] if inward else f), mat=mat, obj=obj)

    def mesh(self) -> MeshTable:
        return MeshTable(np.concatenate(self.pos), np.concatenate(self.tris), self.mat, self.obj)


def look_at(eye, target, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """(4, 4) world_from_camera for a camera at ``eye`` looking at ``target`` (−Z forward, +Y up)."""
    eye, target, up = (np.asarray(v, np.float64) for v in (eye, target, up))
    f = target - eye
    f /= np.linalg.norm(f)
    r = np.cross(f, up)
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = r, u, -f, eye
    return m


def _camera(eye, target, width, height, lens=35.0, **kw) -> CameraDesc:
    return CameraDesc(look_at(eye, target), width, height, lens=lens, **kw)


def cornell_box(width: int = 160, height: int = 120, light: str = "mesh") -> SceneDescription:
    """Cornell box, 2 m wide, lit by a ceiling panel (``light`` = 'mesh' emissive quad or 'area')."""
    b = _Builder()
    white, red, green, lamp = 0, 1, 2, 3
    room = b.object("Room")
    b.quad((-1, 0, 1), (1, 0, 1), (1, 0, -1), (-1, 0, -1), white, room)        # floor, +y
    b.quad((-1, 2, -1), (1, 2, -1), (1, 2, 1), (-1, 2, 1), white, room)        # ceiling, -y
    b.quad((-1, 0, -1), (1, 0, -1), (1, 2, -1), (-1, 2, -1), white, room)      # back, +z
    left, right = b.object("LeftWall"), b.object("RightWall")
    b.quad((-1, 0, 1), (-1, 0, -1), (-1, 2, -1), (-1, 2, 1), red, left)        # +x
    b.quad((1, 0, -1), (1, 0, 1), (1, 2, 1), (1, 2, -1), green, right)         # -x
    b.box((-0.7, 0, -0.6), (-0.1, 1.2, 0.0), white, b.object("TallBox"))
    b.box((0.1, 0, -0.1), (0.7, 0.6, 0.5), white, b.object("ShortBox"))
    names = ["White", "Red", "Green", "Lamp"]
    base = [[0.73, 0.73, 0.73], [0.63, 0.065, 0.05], [0.14, 0.45, 0.091], [0.78, 0.78, 0.78]]
    emission = np.zeros((4, 3))
    areas = AreaLights(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)),
                       np.zeros((0, 3)), [], [])
    radiance = np.array([17.0, 12.0, 4.0])
    if light == "mesh":
        emission[lamp] = radiance
        b.quad((-0.25, 1.99, -0.2), (0.25, 1.99, -0.2), (0.25, 1.99, 0.2), (-0.25, 1.99, 0.2),
               lamp, b.object("Lamp"))
    else:
        lid = b.object("AreaLamp")
        areas = AreaLights([[0, 1.99, 0]], [[0.25, 0, 0]], [[0, 0, 0.2]], [[0, -1, 0]],
                           [radiance], [0], [lid])
    mats = MaterialTable(names, base, np.ones(4), np.zeros(4), np.zeros(4), emission)
    cam = _camera((0, 1, 3.9), (0, 1, 0), width, height, lens=30.0)
    return SceneDescription(b.mesh(), mats, cam, area_lights=areas, object_names=tuple(b.names))


def s_corridor(width: int = 160, height: int = 120) -> SceneDescription:
    """The S-shaped corridor of the paper's Fig. 1 (plan 6 m × 6 m, 2.5 m high).

    Three parallel lanes (z ∈ [0,2], [2,4], [4,6]) are separated by two walls with gaps at
    opposite ends, so light from the panel at the end of the first lane reaches the
    camera in the third lane only after several diffuse bounces.
    """
    b = _Builder()
    wall, lamp = 0, 1
    H = 2.5
    shell = b.object("Shell")
    b.box((0, 0, 0), (6, H, 6), wall, shell, inward=True)
    w1 = b.object("Wall1")   # z = 2, from x = 0 to 4.5 (gap at the far end)
    b.quad((0, 0, 2), (4.5, 0, 2), (4.5, H, 2), (0, H, 2), wall, w1)
    w2 = b.object("Wall2")   # z = 4, from x = 1.5 to 6 (gap at the near end)
    b.quad((1.5, 0, 4), (6, 0, 4), (6, H, 4), (1.5, H, 4), wall, w2)
    light = b.object("LightPanel")
    b.quad((0.01, 0.8, 0.5), (0.01, 0.8, 1.5), (0.01, 1.8, 1.5), (0.01, 1.8, 0.5), lamp, light)
    mats = MaterialTable(["Wall", "Lamp"], [[0.75, 0.75, 0.75], [0.8, 0.8, 0.8]], [1, 1], [0, 0],
                         [0, 0], [[0, 0, 0], [1500.0, 1400.0, 1200.0]])
    cam = _camera((5.9, 1.25, 5.0), (0.0, 1.25, 5.0), width, height, lens=20.0)
    return SceneDescription(b.mesh(), mats, cam, object_names=tuple(b.names))


def icosphere(level: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Unit icosphere: (V, 3) vertices and (T, 3) outward counter-clockwise triangles."""
    t = (1 + 5**0.5) / 2
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t),
         (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
         (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9),
         (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    verts = [np.array(p, float) / np.linalg.norm(p) for p in v]
    faces = f
    for _ in range(level):
        cache: dict[tuple[int, int], int] = {}

        def mid(a, b):
            key = (min(a, b), max(a, b))
            if key not in cache:
                m = verts[a] + verts[b]
                verts.append(m / np.linalg.norm(m))
                cache[key] = len(verts) - 1
            return cache[key]
        new = []
        for a, b, c in faces:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            new += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new
    return np.array(verts), np.array(faces, np.int32)


def furnace(albedo: float = 0.5, emission: float = 0.5, width: int = 10, height: int = 10,
            smooth: bool = False, level: int = 2) -> SceneDescription:
    """Camera inside a closed sphere of uniform albedo and emission.

    Every surface then has radiance Le / (1 − albedo) (pbrt-v4 integrators_test.cpp), so
    every pixel's expected value is that number, whatever the polygonization.
    """
    v, f = icosphere(level)
    v = v * 2.0
    mesh = MeshTable(v, f[:, ::-1].copy(), np.zeros(len(f)), np.zeros(len(f)),
                     normals=-v / 2.0 if smooth else None)
    mats = MaterialTable(["Furnace"], [[albedo] * 3], [1], [0], [0], [[emission] * 3])
    cam = _camera((0, 0, 0), (0, 0, -1), width, height, lens=18.0)
    return SceneDescription(mesh, mats, cam, object_names=("Sphere",))


def point_lit_box(width: int = 24, height: int = 18) -> SceneDescription:
    """Closed box lit by a spot and a point light (exercises delta lights)."""
    b = _Builder()
    b.box((-1, 0, -1), (1, 2, 1), 0, b.object("Box"), inward=True)
    b.box((-0.3, 0, -0.3), (0.3, 0.8, 0.3), 1, b.object("Block"))
    mats = MaterialTable(["White", "Orange"], [[0.7, 0.7, 0.7], [0.8, 0.4, 0.1]], [1, 1], [0, 0],
                         [0, 0], np.zeros((2, 3)))
    pl = PointLights([[0.5, 1.7, 0.5], [-0.5, 1.8, -0.2]], [[3, 3, 3], [4, 2, 1]],
                     [[0, -1, 0], [0, -1, 0]], [-1.0, np.cos(np.radians(35))], [0, 0.3], [0, 0],
                     [b.object("Point"), b.object("Spot")])
    cam = _camera((0, 1, 0.95), (0, 0.6, -1), width, height, lens=16.0)
    return SceneDescription(b.mesh(), mats, cam, point_lights=pl, object_names=tuple(b.names))


def closed_room(width: int = 48, height: int = 36) -> SceneDescription:
    """A closed 3 m × 2.5 m × 3 m room with a block, lit by a ceiling area light.

    Closed and diffuse: all light stays inside (no background, nothing escapes), the
    light is invisible to the camera (area lights are next-event only), so every pixel's
    light has a surface x2 — the whole image is the VPLs' job.
    """
    b = _Builder()
    b.box((-1.5, 0, -1.5), (1.5, 2.5, 1.5), 0, b.object("Room"), inward=True)
    b.box((-0.9, 0, -0.9), (-0.1, 1.1, -0.1), 1, b.object("Block"))
    b.box((0.3, 0, 0.2), (1.0, 0.5, 0.9), 2, b.object("Low block"))
    mats = MaterialTable(["Walls", "Ochre", "Teal"], [[0.7, 0.7, 0.7], [0.7, 0.5, 0.2], [0.2, 0.5, 0.5]],
                         [1, 1, 1], [0, 0, 0], [0, 0, 0], np.zeros((3, 3)))
    area = AreaLights([[0.6, 2.49, -0.6]], [[0.3, 0, 0]], [[0, 0, 0.3]], [[0, -1, 0]],
                      [[30.0, 28.0, 24.0]], [0], [b.object("Ceiling light")])
    cam = _camera((0.0, 1.4, 1.45), (-0.2, 0.7, -1.0), width, height, lens=18.0)
    return SceneDescription(b.mesh(), mats, cam, area_lights=area, object_names=tuple(b.names))


SCENES = {"closed_room": closed_room, "s_corridor": s_corridor, "cornell_box": cornell_box, "furnace": furnace,
          "point_lit_box": point_lit_box}
