"""Built-in scenes as plain descriptions: the S-corridor of the paper's Fig. 1, a Cornell box,
the benchmark scenes (a room lit through a door left ajar, a lamp hidden behind a baffle, a
directly lit scene) and analytic furnace scenes. Used by the command line, the tests and the
benchmarks; ``blend_scenes/build_scenes.py`` saves the benchmark scenes as .blend files.
"""
from __future__ import annotations

import numpy as np

from .description import AreaLights, CameraDesc, MaterialTable, MeshTable, PointLights, SceneDescription


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

    def triangles(self, pos, tris, mat: int, obj: int) -> None:
        """(V, 3) vertices and (T, 3) counter-clockwise triangles of one object."""
        self.pos.append(np.asarray(pos, np.float64))
        self.tris.append(np.asarray(tris, np.int64) + self.n)
        self.mat += [mat] * len(tris)
        self.obj += [obj] * len(tris)
        self.n += len(pos)

    def mesh(self) -> MeshTable:
        return MeshTable(np.concatenate(self.pos), np.concatenate(self.tris), self.mat, self.obj)

    def description(self, materials: MaterialTable, camera: CameraDesc) -> SceneDescription:
        """The scene: this mesh and its object names, ``materials`` and ``camera``."""
        return SceneDescription(self.mesh(), materials, camera, object_names=tuple(self.names))


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
    return b.description(mats, cam)


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


def _diffuse_table(rows) -> MaterialTable:
    """Material table from (name, base colour[, emission]) rows (no emission: black):
    Lambert only (roughness 1, specular 0), i.e. Blender's Diffuse BSDF, or a Principled
    emitter without specular."""
    names = [r[0] for r in rows]
    n = len(rows)
    return MaterialTable(names, [r[1] for r in rows], np.ones(n), np.zeros(n), np.zeros(n),
                         [r[2] if len(r) > 2 else [0, 0, 0] for r in rows])


def _hinged_panel(b: _Builder, hinge, width: float, height: float, thickness: float,
                  angle_deg: float, mat: int, obj: int) -> None:
    """A thin box (a door) of ``width`` along +z from its hinge edge at ``hinge`` (x, 0, z),
    rotated by ``angle_deg`` about the vertical hinge axis towards +x."""
    a = np.radians(angle_deg)
    along = np.array([np.sin(a), 0.0, np.cos(a)])           # from the hinge to the free edge
    across = np.array([np.cos(a), 0.0, -np.sin(a)])         # door thickness direction
    h0 = np.asarray(hinge, np.float64)
    up = np.array([0.0, height, 0.0])
    c = [h0, h0 + width * along, h0 + width * along + thickness * across, h0 + thickness * across]
    lo, hi = c, [p + up for p in c]
    for i in range(4):  # sides, outward (counter-clockwise seen from outside)
        j = (i + 1) % 4
        b.quad(lo[i], hi[i], hi[j], lo[j], mat, obj)
    b.quad(lo[0], lo[3], lo[2], lo[1], mat, obj)            # bottom, −y
    b.quad(hi[0], hi[1], hi[2], hi[3], mat, obj)            # top, +y


def door_ajar(width: int = 160, height: int = 120) -> SceneDescription:
    """A dark room lit only through a door left ajar (benchmark: indirect light, narrow gap).

    The room is x ∈ [0, 3.95], z ∈ [0, 4], 2.5 m high; its 0.1 m thick wall at x = 4 has a
    0.9 m × 2.1 m door opening (z ∈ [1.4, 2.3]). The door, hinged at z = 1.4, is opened 9°
    into the hallway (x ∈ [4.05, 6]), leaving a wedge-shaped gap of about 0.14 m at its free edge. The
    only light is a 1 m² emissive panel on the hallway ceiling, so everything the camera sees
    in the room is lit by light squeezed through the gap and bounced off the hallway walls.
    """
    b = _Builder()
    wall, floor, door, lamp = 0, 1, 2, 3
    H, x = 2.5, 4.0
    b.box((0, 0, 0), (6, H, 4), wall, b.object("Shell"), inward=True)
    sep = b.object("DoorWall")          # 0.1 m thick wall between room and hallway
    z0, z1, dh = 1.4, 2.3, 2.1
    for lo, hi in (((x - 0.05, 0, 0), (x + 0.05, H, z0)), ((x - 0.05, 0, z1), (x + 0.05, H, 4)),
                   ((x - 0.05, dh, z0), (x + 0.05, H, z1))):
        b.box(lo, hi, wall, sep)
    _hinged_panel(b, (x + 0.05, 0.01, z0), z1 - z0 - 0.01, dh - 0.02, 0.04, 9.0, door,
                  b.object("Door"))
    b.quad((0.02, 0.001, 0.3), (3.0, 0.001, 0.3), (3.0, 0.001, 3.7), (0.02, 0.001, 3.7),
           floor, b.object("Rug"))
    light = b.object("HallLamp")
    b.quad((4.5, H - 0.01, 2.5), (5.5, H - 0.01, 2.5), (5.5, H - 0.01, 3.5), (4.5, H - 0.01, 3.5),
           lamp, light)
    mats = _diffuse_table([("Wall", [0.75, 0.75, 0.75]),
                           ("Rug", [0.55, 0.25, 0.15]),
                           ("Door", [0.6, 0.5, 0.35]),
                           ("Lamp", [0.8, 0.8, 0.8], [400.0, 380.0, 340.0])])
    cam = _camera((0.4, 1.5, 0.4), (4.0, 0.9, 2.6), width, height, lens=18.0)
    return b.description(mats, cam)


def baffled_lamp(width: int = 160, height: int = 120) -> SceneDescription:
    """A room whose ceiling lamp hides above a baffle (benchmark: indirect light).

    Room x ∈ [−2.5, 2.5], z ∈ [−2, 2], 2.6 m high. A 0.6 m × 0.6 m emissive panel hangs
    0.1 m under the ceiling; 0.2 m below it a 2 m × 2 m baffle (a thin box) hides it from
    the floor and the camera. The emitter lights the ceiling and the baffle's top; the room
    below is lit only by light bounced off the ceiling.
    """
    b = _Builder()
    wall, blue, wood, lamp = 0, 1, 2, 3
    H = 2.6
    b.box((-2.5, 0, -2), (2.5, H, 2), wall, b.object("Room"), inward=True)
    b.box((-1.0, 2.26, -1.0), (1.0, 2.30, 1.0), wall, b.object("Baffle"))
    b.box((-1.9, 0, -1.6), (-1.1, 0.9, -0.8), blue, b.object("Cabinet"))
    b.box((0.6, 0, -0.4), (1.6, 0.75, 0.4), wood, b.object("Table"))
    y = H - 0.1
    b.quad((-0.3, y, -0.3), (0.3, y, -0.3), (0.3, y, 0.3), (-0.3, y, 0.3), lamp, b.object("Lamp"))
    mats = _diffuse_table([("Wall", [0.8, 0.8, 0.8]),
                           ("Blue", [0.2, 0.3, 0.6]),
                           ("Wood", [0.6, 0.4, 0.2]),
                           ("Lamp", [0.8, 0.8, 0.8], [200.0, 190.0, 170.0])])
    cam = _camera((0.0, 1.3, 1.95), (0.0, 1.1, -2.0), width, height, lens=16.0)
    return b.description(mats, cam)


def directly_lit(width: int = 160, height: int = 120) -> SceneDescription:
    """An easy scene lit mostly directly: blocks on an open floor under a large panel.

    A 6 m × 6 m floor (no walls, black world, so little light bounces back), three blocks and
    a 2 m × 2 m emissive panel 3 m up facing down; the camera sees the lit floor and blocks
    but not the panel.
    """
    b = _Builder()
    floor, red, white, lamp = 0, 1, 2, 3
    b.quad((-3, 0, 3), (3, 0, 3), (3, 0, -3), (-3, 0, -3), floor, b.object("Floor"))
    b.box((-1.2, 0, -0.8), (-0.4, 0.8, 0.0), red, b.object("RedBlock"))
    b.box((0.2, 0, -1.2), (0.8, 1.4, -0.6), white, b.object("TallBlock"))
    b.box((0.5, 0, 0.3), (1.3, 0.4, 1.1), white, b.object("LowBlock"))
    b.quad((-1, 3, -1), (-1, 3, 1), (1, 3, 1), (1, 3, -1), lamp, b.object("Lamp"))
    mats = _diffuse_table([("Floor", [0.5, 0.5, 0.5]),
                           ("Red", [0.7, 0.15, 0.1]),
                           ("White", [0.75, 0.75, 0.75]),
                           ("Lamp", [0.8, 0.8, 0.8], [5.0, 4.8, 4.4])])
    cam = _camera((0.0, 2.2, 4.2), (0.0, 0.3, 0.0), width, height, lens=28.0)
    return b.description(mats, cam)


def specular_box(width: int = 160, height: int = 120) -> SceneDescription:
    """The Cornell box of :func:`cornell_box` (emissive ceiling panel) with a mirror for the
    tall block, turned by 30° (metallic 1, roughness 0, reflectance 0.9) and a glass ball (IOR 1.5,
    roughness 0, radius 0.35 m, a level-3 icosphere) for the short one: mirrors, refraction,
    caustics on the floor, light reflected onto the walls (issue 15)."""
    b = _Builder()
    white, red, green, lamp, mirror, glass = range(6)
    room = b.object("Room")
    b.quad((-1, 0, 1), (1, 0, 1), (1, 0, -1), (-1, 0, -1), white, room)
    b.quad((-1, 2, -1), (1, 2, -1), (1, 2, 1), (-1, 2, 1), white, room)
    b.quad((-1, 0, -1), (1, 0, -1), (1, 2, -1), (-1, 2, -1), white, room)
    b.quad((-1, 0, 1), (-1, 0, -1), (-1, 2, -1), (-1, 2, 1), red, b.object("LeftWall"))
    b.quad((1, 0, -1), (1, 0, 1), (1, 2, 1), (1, 2, -1), green, b.object("RightWall"))
    block = _Builder()                      # the tall block, turned 30° about its vertical axis
    block.box((-0.3, 0, -0.3), (0.3, 1.2, 0.3), mirror, 0)
    c, sn = np.cos(np.radians(30)), np.sin(np.radians(30))
    turn = np.array([[c, 0, sn], [0, 1, 0], [-sn, 0, c]])
    m = block.mesh()
    b.triangles(m.positions.astype(np.float64) @ turn.T + [-0.4, 0, -0.3], m.triangles, mirror,
                b.object("MirrorBlock"))
    v, t = icosphere(3)
    b.triangles(v * 0.35 + [0.4, 0.35, 0.2], t, glass, b.object("GlassBall"))
    b.quad((-0.25, 1.99, -0.2), (0.25, 1.99, -0.2), (0.25, 1.99, 0.2), (-0.25, 1.99, 0.2),
           lamp, b.object("Lamp"))
    names = ["White", "Red", "Green", "Lamp", "Mirror", "Glass"]
    base = [[0.73] * 3, [0.63, 0.065, 0.05], [0.14, 0.45, 0.091], [0.78] * 3, [0.9] * 3, [1.0] * 3]
    emission = np.zeros((6, 3))
    emission[lamp] = [17.0, 12.0, 4.0]
    mats = MaterialTable(names, base, [1, 1, 1, 1, 0, 0], [0, 0, 0, 0, 1, 0], [0, 0, 0, 0, 0.5, 0.5],
                         emission, (), [0, 0, 0, 0, 0, 1], [1.5] * 6)
    cam = _camera((0, 1, 3.9), (0, 1, 0), width, height, lens=30.0)
    return SceneDescription(b.mesh(), mats, cam, object_names=tuple(b.names))


SCENES = {"closed_room": closed_room, "s_corridor": s_corridor, "cornell_box": cornell_box, "furnace": furnace,
          "point_lit_box": point_lit_box, "door_ajar": door_ajar, "baffled_lamp": baffled_lamp,
          "directly_lit": directly_lit, "specular_box": specular_box}

#: The benchmark scenes, each also saved as ``blend_scenes/<name>.blend`` (160 × 120).
BENCHMARK_SCENES = ("s_corridor", "cornell_box", "door_ajar", "baffled_lamp", "directly_lit")


def _room_shell(b: _Builder, lo, hi, wall: int, floor: int, obj: int, front: int | None = None) -> None:
    """A closed room (inward faces): the floor (−y face) in ``floor``, the front (+z) wall in
    ``front`` (default ``wall``), the rest in ``wall``."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    b.quad((x0, y0, z1), (x1, y0, z1), (x1, y0, z0), (x0, y0, z0), floor, obj)      # floor, +y
    b.quad((x0, y1, z0), (x1, y1, z0), (x1, y1, z1), (x0, y1, z1), wall, obj)      # ceiling, −y
    b.quad((x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0), wall, obj)      # back, +z
    b.quad((x1, y0, z1), (x0, y0, z1), (x0, y1, z1), (x1, y1, z1),
           wall if front is None else front, obj)                                  # front, −z
    b.quad((x0, y0, z1), (x0, y0, z0), (x0, y1, z0), (x0, y1, z1), wall, obj)      # left, +x
    b.quad((x1, y0, z0), (x1, y0, z1), (x1, y1, z1), (x1, y1, z0), wall, obj)      # right, −x


def _open_box(b: _Builder, lo, hi, mat: int, obj: int, open_face: int) -> None:
    """An axis-aligned box (single-sided walls, seen from both sides) without face
    ``open_face`` (the order of :meth:`_Builder.box`: −x, +x, −y, +y, −z, +z)."""
    part = _Builder()
    part.box(lo, hi, mat, 0)
    m = part.mesh()
    keep = [k for k in range(6) if k != open_face]
    tris = np.concatenate([m.triangles[2 * k:2 * k + 2] for k in keep])
    b.triangles(m.positions.astype(np.float64), tris, mat, obj)


def _table(b: _Builder, x0, z0, x1, z1, h: float, top: float, leg: float, mat: int, obj: int) -> None:
    """A table ``h`` high over x ∈ [x0, x1], z ∈ [z0, z1]: a top slab ``top`` thick and four
    square legs ``leg`` wide, set 0.02 m in from its edges."""
    b.box((x0, h - top, z0), (x1, h, z1), mat, obj)
    for x, z in ((x0, z0), (x1 - leg, z0), (x0, z1 - leg), (x1 - leg, z1 - leg)):
        b.box((x + 0.02, 0, z + 0.02), (x + leg - 0.02, h - top, z + leg - 0.02), mat, obj)


def _egg(level: int = 3, height: float = 0.26, radius: float = 0.09) -> tuple[np.ndarray, np.ndarray]:
    """An egg centred at the origin: an icosphere scaled to ``height`` along y, ``radius``
    across, the top end 30 % narrower than the bottom one."""
    v, t = icosphere(level)
    taper = 1.0 - 0.15 * v[:, 1]
    return np.stack([v[:, 0] * radius * taper, v[:, 1] * height / 2, v[:, 2] * radius * taper], 1), t


def _mirror_glass_table(rows) -> MaterialTable:
    """Material table from (name, kind, base colour[, emission or roughness]) rows; kind
    'diffuse' (Diffuse BSDF), 'lamp' (a Principled emitter without specular), 'mirror' (a
    Glossy BSDF: metallic 1, specular 0.5, roughness ``rows[3]`` or 0) or 'glass' (a Glass
    BSDF: transmission 1, IOR 1.5, specular 0.5, roughness ``rows[3]`` or 0) — each exactly the
    row the add-on exports for that Blender node (blend_scenes/build_scenes.py)."""
    n = len(rows)
    rough, metal, spec, trans = np.ones(n), np.zeros(n), np.zeros(n), np.zeros(n)
    emission = np.zeros((n, 3))
    for i, r in enumerate(rows):
        kind = r[1]
        if kind == "lamp":
            emission[i] = r[3]
        elif kind in ("mirror", "glass"):
            rough[i] = r[3] if len(r) > 3 else 0.0
            spec[i] = 0.5
            metal[i] = 1.0 if kind == "mirror" else 0.0
            trans[i] = 1.0 if kind == "glass" else 0.0
    return MaterialTable([r[0] for r in rows], [r[2] for r in rows], rough, metal, spec, emission,
                         (), trans, np.full(n, 1.5))


def veach_room(width: int = 160, height: int = 120) -> SceneDescription:
    """A room in the spirit of Veach's bidirectional test room (Veach 1997, fig. 10.3):
    benchmark for indirect light through glass.

    Room x ∈ [−2.5, 2.5], z ∈ [−2, 2], 2.7 m high (walls 0.7, floor 0.5). The only light is
    a 0.3 m × 0.3 m emissive quad (radiance 300) facing up inside the open-topped shade of a
    floor lamp (1.65 m, the shade's rim 0.25 m above the lamp): it lights a patch of the
    ceiling, and the room is lit by light bounced off it. On the table in front of the camera
    stand a smooth glass egg (0.26 m tall, IOR 1.5, a level-3 icosphere) and a chrome ball
    (metallic 1, roughness 0, reflectance 0.9); a cabinet against the left wall.
    """
    b = _Builder()
    wall, floor, wood, shade, glass, chrome, blue, lamp = range(8)
    H = 2.7
    _room_shell(b, (-2.5, 0, -2), (2.5, H, 2), wall, floor, b.object("Room"))
    _table(b, -0.1, -1.3, 1.3, -0.4, 0.76, 0.04, 0.08, wood, b.object("Table"))
    v, t = _egg(3)
    b.triangles(v + [0.45, 0.76 + 0.131, -0.75], t, glass, b.object("GlassEgg"))
    v, t = icosphere(2)
    b.triangles(v * 0.07 + [0.85, 0.76 + 0.0705, -0.6], t, chrome, b.object("ChromeBall"))
    b.box((-2.45, 0, -1.6), (-1.9, 0.9, -0.4), blue, b.object("Cabinet"))
    lx, lz, ly = 1.9, -1.45, 1.65                         # the floor lamp: base, pole, shade
    stand = b.object("LampStand")
    b.box((lx - 0.15, 0, lz - 0.15), (lx + 0.15, 0.03, lz + 0.15), shade, stand)
    b.box((lx - 0.02, 0.03, lz - 0.02), (lx + 0.02, ly - 0.02, lz + 0.02), shade, stand)
    _open_box(b, (lx - 0.19, ly - 0.02, lz - 0.19), (lx + 0.19, ly + 0.25, lz + 0.19), shade,
              b.object("LampShade"), open_face=3)
    y = ly
    b.quad((lx - 0.15, y, lz + 0.15), (lx + 0.15, y, lz + 0.15), (lx + 0.15, y, lz - 0.15),
           (lx - 0.15, y, lz - 0.15), lamp, b.object("Lamp"))
    mats = _mirror_glass_table([("Wall", "diffuse", [0.7, 0.7, 0.7]),
                                ("Floor", "diffuse", [0.5, 0.5, 0.5]),
                                ("Wood", "diffuse", [0.55, 0.35, 0.2]),
                                ("Shade", "diffuse", [0.1, 0.1, 0.1]),
                                ("Glass", "glass", [1.0, 1.0, 1.0]),
                                ("Chrome", "mirror", [0.9, 0.9, 0.9]),
                                ("Blue", "diffuse", [0.2, 0.3, 0.55]),
                                ("Lamp", "lamp", [0.8, 0.8, 0.8], [300.0, 290.0, 260.0])])
    cam = _camera((-0.55, 1.3, 0.55), (0.75, 1.0, -1.0), width, height, lens=28.0)
    return b.description(mats, cam)


def mirror_glass_room(width: int = 160, height: int = 120) -> SceneDescription:
    """An interior with a wall mirror, a glass partition and a rough-glass ball, lit by a
    lamp aimed at a wall (benchmark: indirect light seen in a mirror and through glass).

    Room x ∈ [−2.5, 2.5], z ∈ [−2, 2], 2.6 m high (walls 0.7, floor 0.5). The only light is
    a 0.6 m × 0.4 m emissive quad (radiance 200) on a stand 0.6 m from the right wall,
    facing it, in a shallow shade (7 cm behind it) open only towards the wall (a wall washer): it
    lights the right wall, and the room is lit by light bounced off it. The back wall holds a 2.4 m × 1.7 m mirror
    (metallic 1, roughness 0, reflectance 0.9) in front of which a smooth glass partition
    (1.6 m × 2 m, 4 cm thick, IOR 1.5) stands out from the left wall; on a low table a
    rough-glass ball (roughness 0.3, a level-3 icosphere); a red sofa and a cabinet. The
    camera looks at the mirror, which shows the room behind the camera.
    """
    b = _Builder()
    wall, floor, wood, shade, mirror, glass, frosted, red, green, lamp = range(10)
    H = 2.6
    room = b.object("Room")
    _room_shell(b, (-2.5, 0, -2), (2.5, H, 2), wall, floor, room, front=green)
    b.box((-1.6, 0.5, -1.99), (0.8, 2.2, -1.97), mirror, b.object("Mirror"))
    frame = b.object("MirrorFrame")
    for lo, hi in (((-1.66, 0.44, -1.99), (0.86, 0.5, -1.95)), ((-1.66, 2.2, -1.99), (0.86, 2.26, -1.95)),
                   ((-1.66, 0.5, -1.99), (-1.6, 2.2, -1.95)), ((0.8, 0.5, -1.99), (0.86, 2.2, -1.95))):
        b.box(lo, hi, wood, frame)
    b.box((-2.49, 0.06, -0.62), (-0.95, 2.0, -0.58), glass, b.object("GlassPartition"))
    post = b.object("PartitionFrame")
    b.box((-2.49, 0.0, -0.64), (-0.95, 0.06, -0.56), wood, post)
    b.box((-0.95, 0.0, -0.64), (-0.89, 2.0, -0.56), wood, post)
    _table(b, -0.2, -1.1, 0.8, -0.5, 0.45, 0.04, 0.08, wood, b.object("LowTable"))
    v, t = icosphere(3)
    b.triangles(v * 0.18 + [0.3, 0.45 + 0.181, -0.8], t, frosted, b.object("RoughGlassBall"))
    sofa = b.object("Sofa")                                   # against the front wall
    b.box((-1.8, 0, 1.1), (0.2, 0.42, 1.95), red, sofa)
    b.box((-1.8, 0.42, 1.7), (0.2, 0.85, 1.95), red, sofa)
    for x in (-1.8, 0.0):
        b.box((x, 0.42, 1.1), (x + 0.2, 0.62, 1.7), red, sofa)
    b.box((1.6, 0, -1.9), (2.45, 1.0, -1.3), wood, b.object("Cabinet"))
    lx, ly, lz = 1.9, 1.5, 0.3                                # the wall washer, facing +x
    _open_box(b, (lx - 0.07, ly - 0.25, lz - 0.35), (lx + 0.06, ly + 0.25, lz + 0.35), shade,
              b.object("LampShade"), open_face=1)
    b.quad((lx, ly - 0.2, lz + 0.3), (lx, ly - 0.2, lz - 0.3), (lx, ly + 0.2, lz - 0.3),
           (lx, ly + 0.2, lz + 0.3), lamp, b.object("Lamp"))
    stand = b.object("LampStand")
    b.box((lx - 0.2, 0, lz - 0.2), (lx + 0.1, 0.03, lz + 0.2), shade, stand)
    b.box((lx - 0.05, 0.03, lz - 0.02), (lx - 0.01, ly - 0.25, lz + 0.02), shade, stand)
    mats = _mirror_glass_table([("Wall", "diffuse", [0.7, 0.7, 0.7]),
                                ("Floor", "diffuse", [0.5, 0.5, 0.5]),
                                ("Wood", "diffuse", [0.55, 0.35, 0.2]),
                                ("Shade", "diffuse", [0.1, 0.1, 0.1]),
                                ("Mirror", "mirror", [0.9, 0.9, 0.9]),
                                ("Glass", "glass", [1.0, 1.0, 1.0]),
                                ("RoughGlass", "glass", [0.75, 0.88, 1.0], 0.3),
                                ("Red", "diffuse", [0.6, 0.12, 0.1]),
                                ("Green", "diffuse", [0.45, 0.6, 0.5]),
                                ("Lamp", "lamp", [0.8, 0.8, 0.8], [120.0, 114.0, 102.0])])
    cam = _camera((1.3, 1.45, 1.6), (-0.5, 1.1, -2.0), width, height, lens=22.0)
    return b.description(mats, cam)


SCENES.update(veach_room=veach_room, mirror_glass_room=mirror_glass_room)
