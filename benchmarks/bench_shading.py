"""Cost of shading programs on a room with 60 textured materials (issue 14, "Measured").

The scene: a closed 6 × 3 × 6 m room whose floor, ceiling and walls are split into tiles
(8 × 8 per face, 2 triangles each), one of 60 materials per tile. Every material reads one
of 8 procedurally made 256² images through UV Map → Mapping (its own scale) → Image
Texture (Linear, REPEAT) → Hue/Saturation → base colour, roughness from a Math node on
the texture's alpha, and every third one a tangent-space Normal Map from a 256² normal
image. A ceiling quad lamp lights it.

It renders the scene with its programs and with the programs removed (the same rows'
constants), at the same settings — the two interleaved, best of ``--repeat`` each, so machine
load hits both alike — and reports the share of render time spent in shading,
(t_programs − t_constants)/t_programs, for PATH and ERCUTS. Memory: the textures' share of
the core's memory plan (``ercuts_core.memory.plan_for``: textures, UVs, tangents) and the
peak RSS (``VmHWM``) of a fresh process rendering each version (PATH). Export (bpy module):
60 Principled materials with a 512² colour image and a 512² normal map each (120 images)
on 60 UV-mapped planes, through ``addon.export.export_scene``, best of ``--repeat``.

Run: ``.venv/bin/python benchmarks/bench_shading.py`` (≈ 2 min on 2 cores) →
``benchmarks/results/shading.md`` + ``.json``. ``--no-export`` skips the bpy part.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
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


def _plain(d: SceneDescription) -> SceneDescription:
    """The same scene with every program and image removed (each row keeps its constants)."""
    m = d.materials
    return d.replace(materials=MaterialTable(m.names, m.base_color, m.roughness, m.metallic, m.specular,
                                             m.emission), textures=TextureTable())


def _timed(desc, settings: RenderSettings) -> float:
    t = time.perf_counter()
    render(desc, settings)
    return time.perf_counter() - t


def shading_share(d: SceneDescription, repeat: int) -> dict:
    """{engine: {programs_s, constants_s, share}}: best of ``repeat`` interleaved renders."""
    plain = _plain(d)
    out = {}
    for name, kw in [("PATH", dict(samples=16)),
                     ("ERCUTS", dict(rough_samples=4, chain_length=20, chains_per_pixel=0.25))]:
        s = RenderSettings(integrator=name, seed=1, **kw)
        tp, tc = [], []
        for _ in range(repeat):
            tp.append(_timed(d, s))
            tc.append(_timed(plain, s))
        out[name] = dict(programs_s=min(tp), constants_s=min(tc), share=(min(tp) - min(tc)) / min(tp))
        print(f"{name:7s} programs {min(tp):6.2f} s  constants {min(tc):6.2f} s  "
              f"shading share {100 * out[name]['share']:5.1f} %", flush=True)
    return out


_CHILD = r"""
import json, sys
sys.path[:0] = [{root!r}, {here!r}]
import bench_shading as b
from ercuts_core import RenderSettings, render
def status(key):
    for line in open("/proc/self/status"):
        if line.startswith(key + ":"):
            return int(line.split()[1]) / 1024.0
d = b.textured_room({w}, {h})
d = d if {programs!r} else b._plain(d)
base = status("VmRSS")
r = render(d, RenderSettings(integrator="PATH", samples=4, seed=1))
print("RESULT " + json.dumps(dict(baseline_mb=base, peak_mb=status("VmHWM"),
                                  estimate_mb=r.stats["memory_estimate_mb"])))
"""


def peak_rss(w: int, h: int, programs: bool) -> dict:
    """Peak RSS of a fresh process rendering the scene (PATH, 4 spp), MiB."""
    here = os.path.dirname(os.path.abspath(__file__))
    code = _CHILD.format(root=os.path.dirname(here), here=here, w=w, h=h, programs=programs)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    return json.loads(next(ln for ln in out.splitlines() if ln.startswith("RESULT "))[7:])


def export_time(repeat: int, n_materials: int = 60, size: int = 512) -> dict:
    """Seconds to export ``n_materials`` textured materials (2 images of ``size``² each)."""
    import bpy

    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    import addon
    from addon import compat
    from addon.export import export_scene

    if not hasattr(bpy.types.Scene, "ercuts"):
        addon.register()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    rng = np.random.default_rng(0)
    for k in range(n_materials):
        imgs = []
        for kind, space in (("col", "sRGB"), ("nrm", "Non-Color")):
            img = bpy.data.images.new(f"{kind}{k}", size, size)
            img.colorspace_settings.name = space
            img.pixels.foreach_set(rng.random(size * size * 4, dtype=np.float32))
            imgs.append(img)
        mat = bpy.data.materials.new(f"M{k}")
        compat.enable_nodes(mat)
        nt = mat.node_tree
        bsdf = next(n for n in nt.nodes if n.type == "BSDF_PRINCIPLED")
        col, nrm = (nt.nodes.new("ShaderNodeTexImage") for _ in range(2))
        col.image, nrm.image = imgs
        nmap = nt.nodes.new("ShaderNodeNormalMap")
        nt.links.new(col.outputs["Color"], bsdf.inputs["Base Color"])
        nt.links.new(nrm.outputs["Color"], nmap.inputs["Color"])
        nt.links.new(nmap.outputs["Normal"], compat.principled_input(bsdf, "normal"))
        me = bpy.data.meshes.new(f"P{k}")
        x = 2.5 * (k % 10)
        y = 2.5 * (k // 10)
        me.from_pydata([(x, y, 0), (x + 2, y, 0), (x + 2, y + 2, 0), (x, y + 2, 0)], [], [(0, 1, 2, 3)])
        uv = me.uv_layers.new(name="UVMap")
        for li, c in enumerate([(0, 0), (1, 0), (1, 1), (0, 1)]):
            uv.data[li].uv = c
        me.materials.append(mat)
        bpy.context.scene.collection.objects.link(bpy.data.objects.new(f"P{k}", me))
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.location = (12, 6, 30)
    bpy.context.scene.collection.objects.link(cam)
    bpy.context.scene.camera = cam
    times, ex = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        ex = export_scene(bpy.context.evaluated_depsgraph_get())
        times.append(time.perf_counter() - t)
    out = dict(materials=n_materials, images=2 * n_materials, image_size=size, export_s=min(times),
               texture_mib=ex.description.textures.nbytes / 2**20, warnings=len(ex.warnings))
    print(f"export: {n_materials} materials, {2 * n_materials} images of {size}²: {min(times):.2f} s "
          f"(best of {repeat}), {out['texture_mib']:.0f} MiB of texture", flush=True)
    return out


def _report(res: dict) -> str:
    m = res["memory"]
    lines = ["# Shading cost on a room with 60 textured materials", "",
             f"Written by `benchmarks/bench_shading.py` on {res['date']} ({res['cpus']} cores; the "
             f"1-minute load average before the run was {res['load']:.1f}). Scene: "
             f"{res['scene']['materials']} textured materials in use, {res['scene']['triangles']} "
             f"triangles, {res['scene']['images']} images of 256², {res['width']}×{res['height']} "
             "pixels.", "",
             "| engine | with programs (s) | constants only (s) | shading share |", "|---|---|---|---|"]
    for name, r in res["shading"].items():
        lines.append(f"| {name} | {r['programs_s']:.2f} | {r['constants_s']:.2f} | "
                     f"{100 * r['share']:.0f} % |")
    lines += ["", "Best of the interleaved repeats; share = (t_programs − t_constants)/t_programs. "
              "Timings on a shared machine are inflated by its load (see above): rerun on a quiet one.", "",
              "| memory | MiB |", "|---|---|",
              f"| textures (float32 RGBA, the description) | {m['texture_mib']:.2f} |",
              "| the memory plan's 'textures' part (textures + UVs + tangents) | "
              f"{m['plan_textures_mib']:.2f} |",
              f"| the plan's total estimate, with / without programs | {m['estimate_mib']:.0f} / "
              f"{m['estimate_plain_mib']:.0f} |",
              f"| peak RSS of a fresh process, with / without programs and images (PATH, 4 spp) | "
              f"{m['rss_programs']['peak_mb']:.0f} / {m['rss_constants']['peak_mb']:.0f} |",
              f"| RSS before rendering (interpreter, numpy, embree, description), with / without | "
              f"{m['rss_programs']['baseline_mb']:.0f} / {m['rss_constants']['baseline_mb']:.0f} |", "",
              "The images live in the description, so they are in the RSS before rendering; the "
              "render's own peak (peak − before) is what the plan's other parts estimate.", ""]
    if res.get("export"):
        e = res["export"]
        lines += [f"Export (bpy {res['export_blender']}): {e['materials']} Principled materials with "
                  f"{e['images']} images of {e['image_size']}² (colour + normal map each) in "
                  f"{e['export_s']:.2f} s; {e['texture_mib']:.0f} MiB of float32 texture.", ""]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    import datetime as dt

    from ercuts_core.memory import plan_for

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--width", type=int, default=64)
    ap.add_argument("--height", type=int, default=48)
    ap.add_argument("--no-export", action="store_true", help="skip the bpy export timing")
    results = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results")
    ap.add_argument("--out", default=os.path.join(results, "shading"), help="results path without extension")
    args = ap.parse_args(argv)
    load = os.getloadavg()[0]
    d = textured_room(args.width, args.height)
    n_used = len(set(d.mesh.material_ids.tolist())) - 1
    print(f"{n_used} textured materials in use, {d.mesh.n_triangles} triangles, {len(d.textures)} "
          f"images, texture memory {d.textures.nbytes / 2**20:.1f} MiB (float32 RGBA)", flush=True)
    s = RenderSettings(integrator="PATH", samples=4, seed=1)
    plan, plan_plain = plan_for(d, s), plan_for(_plain(d), s)
    memory = dict(texture_mib=d.textures.nbytes / 2**20,
                  plan_textures_mib=plan.parts["textures"] / 2**20,
                  estimate_mib=plan.total / 2**20, estimate_plain_mib=plan_plain.total / 2**20,
                  rss_programs=peak_rss(args.width, args.height, True),
                  rss_constants=peak_rss(args.width, args.height, False))
    print(f"memory plan: textures part {memory['plan_textures_mib']:.2f} MiB; peak RSS "
          f"{memory['rss_programs']['peak_mb']:.0f} MiB with programs, "
          f"{memory['rss_constants']['peak_mb']:.0f} MiB without", flush=True)
    res = dict(date=dt.date.today().isoformat(), cpus=os.cpu_count(), load=load, width=args.width,
               height=args.height, scene=dict(materials=n_used, triangles=d.mesh.n_triangles,
                                              images=len(d.textures)),
               shading=shading_share(d, args.repeat), memory=memory)
    if not args.no_export:
        import bpy

        res["export"] = export_time(args.repeat)
        res["export_blender"] = bpy.app.version_string
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out + ".json", "w") as fh:
        json.dump(res, fh, indent=1)
    with open(args.out + ".md", "w") as fh:
        fh.write(_report(res))
    print(f"bench_shading: wrote {args.out}.md and .json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
