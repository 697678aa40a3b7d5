"""Cost of shading programs on a room with 60 textured materials (issue 14, "Measured").

The scene: a closed 6 × 3 × 6 m room whose floor, ceiling and walls are split into tiles
(8 × 8 per face, 2 triangles each), one of 60 materials per tile. Every material reads one
of 8 procedurally made 256² images through UV Map → Mapping (its own scale) → Image
Texture (Linear, REPEAT) → Hue/Saturation → base colour, roughness from a Math node on
the texture's alpha, and every third one a tangent-space Normal Map from a 256² normal
image. A ceiling quad lamp lights it.

It renders the scene with its programs and with the programs removed (the same rows'
constants), at the same settings, and reports the texture memory and the share of render
time spent in shading: (t_programs − t_constants)/t_programs, best of ``--repeat`` runs.

Run: ``.venv/bin/python benchmarks/bench_shading.py`` (≈ 1 min on 2 shared cores).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from ercuts_core import RenderSettings, render  # noqa: E402
from ercuts_core.description import CameraDesc, MaterialTable, MeshTable, SceneDescription  # noqa: E402
from ercuts_core.scenes import look_at  # noqa: E402
from ercuts_core.shading.textures import TextureTable  # noqa: E402

N_MATERIALS = 60
N_IMAGES = 8
TILES = 8


def _images(rng: np.random.Generator) -> list[np.ndarray]:
    """8 colour images (smooth noise + stripes) and one tangent-space normal image."""
    y, x = np.mgrid[0:256, 0:256] / 256.0
    out = []
    for k in range(N_IMAGES):
        f = rng.uniform(2, 12, 3)
        rgb = 0.5 + 0.4 * np.sin(2 * np.pi * (f[:, None, None] * x + (k + 1) * y + rng.uniform(0, 1, 3)[:, None, None]))
        alpha = 0.5 + 0.5 * np.sin(2 * np.pi * 6 * x * y)
        out.append(np.concatenate([rgb.transpose(1, 2, 0), alpha[..., None]], axis=2).astype(np.float32))
    nx, ny = 0.3 * np.sin(2 * np.pi * 8 * x), 0.3 * np.cos(2 * np.pi * 8 * y)
    nz = np.sqrt(1 - nx ** 2 - ny ** 2)
    normal = np.stack([nx * 0.5 + 0.5, ny * 0.5 + 0.5, nz * 0.5 + 0.5, np.ones_like(nx)], axis=2)
    out.append(normal.astype(np.float32))
    return out


def _program(k: int, rng: np.random.Generator) -> str:
    scale = float(rng.uniform(0.5, 3.0))
    nodes = [{"type": "UVMAP"},
             {"type": "MAPPING", "inputs": {"Vector": {"node": 0, "socket": "UV"}, "Location": [0, 0, 0],
                                            "Rotation": [0, 0, float(rng.uniform(0, 1))], "Scale": [scale] * 3},
              "params": {"vector_type": "POINT"}},
             {"type": "TEX_IMAGE", "inputs": {"Vector": {"node": 1, "socket": "Vector"}},
              "params": {"texture": k % N_IMAGES, "interpolation": "Linear", "extension": "REPEAT"}},
             {"type": "HUE_SAT", "inputs": {"Hue": float(rng.uniform(0.3, 0.7)), "Saturation": 1.0, "Value": 0.9,
                                            "Fac": 1.0, "Color": {"node": 2, "socket": "Color"}}},
             {"type": "MATH", "inputs": {"Value": {"node": 2, "socket": "Alpha"}, "Value_001": 0.6, "Value_002": 0.2},
              "params": {"operation": "MULTIPLY_ADD", "use_clamp": True}}]
    outputs = {"base_color": {"node": 3, "socket": "Color"}, "roughness": {"node": 4, "socket": "Value"},
               "specular": 0.5}
    if k % 3 == 0:
        nodes += [{"type": "TEX_IMAGE", "inputs": {"Vector": {"node": 1, "socket": "Vector"}},
                   "params": {"texture": N_IMAGES, "interpolation": "Linear", "extension": "REPEAT"}},
                  {"type": "NORMAL_MAP", "inputs": {"Strength": 1.0, "Color": {"node": 5, "socket": "Color"}},
                   "params": {"space": "TANGENT"}}]
        outputs["normal"] = {"node": 6, "socket": "Normal"}
    return json.dumps({"version": 1, "nodes": nodes, "outputs": outputs})


def _face(origin, du, dv, n):
    """Tiles of a face: positions (n²·4, 3), triangles (2n², 3), per-corner UVs (2n², 3, 2)."""
    origin, du, dv = (np.asarray(a, float) for a in (origin, du, dv))
    pos, tris, uvs = [], [], []
    for i in range(n):
        for j in range(n):
            a = origin + du * i / n + dv * j / n
            quad = [a, a + du / n, a + du / n + dv / n, a + dv / n]
            base = len(pos)
            pos += quad
            tris += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
            uv = np.array([[i, j], [i + 1, j], [i + 1, j + 1], [i, j + 1]], float) / n * np.linalg.norm(du)
            uvs += [uv[[0, 1, 2]], uv[[0, 2, 3]]]
    return np.array(pos), np.array(tris), np.array(uvs)


def textured_room(width: int = 64, height: int = 48, seed: int = 0) -> SceneDescription:
    rng = np.random.default_rng(seed)
    W, H = 6.0, 3.0
    faces = [((0, 0, 0), (0, 0, W), (W, 0, 0)),          # floor (+y)
             ((0, H, 0), (W, 0, 0), (0, 0, W)),          # ceiling (−y)
             ((0, 0, 0), (W, 0, 0), (0, H, 0)),          # back (+z)
             ((0, 0, W), (0, H, 0), (W, 0, 0)),          # front (−z)
             ((0, 0, 0), (0, H, 0), (0, 0, W)),          # left (+x)
             ((W, 0, 0), (0, 0, W), (0, H, 0))]          # right (−x)
    pos, tris, uvs = [], [], []
    for o, du, dv in faces:
        p, t, uv = _face(o, du, dv, TILES)
        tris.append(t + sum(len(q) for q in pos))
        pos.append(p)
        uvs.append(uv)
    n_tiles = sum(len(t) for t in tris) // 2
    mat_ids = np.repeat(rng.integers(0, N_MATERIALS, n_tiles), 2)
    lamp = np.array([[2.5, H - 0.01, 2.5], [3.5, H - 0.01, 2.5], [3.5, H - 0.01, 3.5], [2.5, H - 0.01, 3.5]])
    n_v = sum(len(p) for p in pos)
    pos.append(lamp)
    tris.append(np.array([[0, 1, 2], [0, 2, 3]]) + n_v)
    uvs.append(np.zeros((2, 3, 2)))
    mat_ids = np.append(mat_ids, [N_MATERIALS, N_MATERIALS])
    obj = np.append(np.zeros(len(mat_ids) - 2, int), [1, 1])
    names = tuple(f"Tex{k:02d}" for k in range(N_MATERIALS)) + ("Lamp",)
    base = np.vstack([rng.uniform(0.3, 0.8, (N_MATERIALS, 3)), [[0.8] * 3]])
    emission = np.zeros((N_MATERIALS + 1, 3))
    emission[-1] = 40.0
    programs = tuple(_program(k, rng) for k in range(N_MATERIALS)) + ("",)
    mats = MaterialTable(names, base, np.full(N_MATERIALS + 1, 0.5), np.zeros(N_MATERIALS + 1),
                         np.full(N_MATERIALS + 1, 0.5), emission, programs)
    mesh = MeshTable(np.vstack(pos), np.vstack(tris), mat_ids, obj, uvs=np.concatenate(uvs))
    cam = CameraDesc(look_at((0.5, 1.5, 5.5), (4.0, 1.2, 1.0)), width, height, lens=20.0)
    images = _images(rng)
    return SceneDescription(mesh, mats, cam, object_names=("Room", "Lamp"),
                            textures=TextureTable(tuple(f"img{i}" for i in range(len(images))), tuple(images)))


def _best(desc, settings: RenderSettings, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        render(desc, settings)
        times.append(time.perf_counter() - t)
    return min(times)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=2)
    args = ap.parse_args(argv)
    d = textured_room()
    m = d.materials
    plain = d.replace(materials=MaterialTable(m.names, m.base_color, m.roughness, m.metallic, m.specular,
                                              m.emission))
    print(f"{len(set(d.mesh.material_ids.tolist())) - 1} textured materials in use, "
          f"{d.mesh.n_triangles} triangles, {len(d.textures)} images, "
          f"texture memory {d.textures.nbytes / 2**20:.1f} MiB (float32 RGBA)")
    for name, kw in [("PATH", dict(samples=16)),
                     ("ERCUTS", dict(rough_samples=4, chain_length=20, chains_per_pixel=0.25))]:
        s = RenderSettings(integrator=name, seed=1, **kw)
        t_prog, t_const = _best(d, s, args.repeat), _best(plain, s, args.repeat)
        share = (t_prog - t_const) / t_prog
        print(f"{name:7s} programs {t_prog:6.2f} s  constants {t_const:6.2f} s  shading share {100 * share:5.1f} %")
    return 0


if __name__ == "__main__":
    sys.exit(main())
