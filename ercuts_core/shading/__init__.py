"""Shading programs: Blender node trees compiled to small value graphs the core evaluates
vectorized over all hits of a material at once (issue 14).

Split of work
-------------
* The add-on (``addon/export/shaders.py``) flattens a material's node tree (groups, reroutes,
  closures) into a *program*: value nodes only. Closures never reach the core: a Mix Shader
  ``mix(f, A, B)`` becomes per-parameter ``MIX`` nodes blending A's and B's parameters with
  ``f`` (exact for emission and for diffuse/diffuse mixes; an approximation for mixes of
  different GGX lobes, documented in the README's node table); an Add Shader adds colours and
  emission; a Transparent BSDF contributes to ``alpha`` (alpha 0 = fully transparent).
* The core (``ercuts_core.shading``) evaluates programs per hit: texture lookups, colour and
  math nodes, normal maps and bump, giving the lobe parameters of :mod:`ercuts_core.bsdf`,
  the emission, the alpha and the shading normal.

Program format (version 1), a JSON string per material row (``MaterialTable.programs``;
"" = the row's constants only)::

    {"version": 1,
     "nodes": [{"type": <NODE TYPE>, "inputs": {<socket>: <value>, ...},
                "params": {...}}, ...],          # topological order: refs point backwards
     "outputs": {"base_color": <value>, "roughness": <value>, "metallic": <value>,
                 "specular": <value>, "emission": <value>,   # radiance = colour × strength
                 "alpha": <value>, "normal": <value> | null,  # normal: world-space vector
                 "transmission": <value>, "ior": <value>,     # optional: glass lobe
                 "translucency": <value>},                    # optional: Translucent BSDF
     "bump_shadowing": "NONE" | "CHIANG2019" | "ESTEVEZ2019"}   # optional, default NONE

    <value> := number | [x, y, z] | {"node": <index>, "socket": <output socket name>}

Missing outputs take the row's constants in ``MaterialTable``. Node types are Blender's
``node.type`` strings; sockets are Blender's socket *names* (Blender 4.x/5.x spelling;
the exporter translates 3.x names). Inputs not given take the node's defaults as Blender
defines them; the exporter writes every unlinked input's value explicitly anyway.

=================  ============================================  ==========================
type               params                                        outputs
=================  ============================================  ==========================
TEX_IMAGE          texture (int, row of ``TextureTable``),        Color, Alpha
                   interpolation ('Closest'|'Linear'|'Cubic'),
                   extension ('REPEAT'|'EXTEND'|'CLIP'|'MIRROR')
TEX_COORD          —                                             UV, Generated, Object, Normal
UVMAP              —   (the active render UV map)                UV
MAPPING            vector_type ('POINT'|'TEXTURE'|'VECTOR'|      Vector
                   'NORMAL'); inputs Vector, Location, Rotation
                   (XYZ Euler, radians), Scale
SEPARATE_COLOR     mode ('RGB'|'HSV'|'HSL')                      Red, Green, Blue (first..third)
COMBINE_COLOR      mode                                          Color
SEPXYZ / COMBXYZ   —                                             X, Y, Z / Vector
MIX                data_type ('FLOAT'|'RGBA'|'VECTOR'),           Result
                   blend_type (MIX, ADD, MULTIPLY, SUBTRACT,
                   SCREEN, DIVIDE, DIFFERENCE, DARKEN, LIGHTEN,
                   OVERLAY, ...), clamp_factor, clamp_result;
                   inputs Factor, A, B
MATH               operation (Blender's enum), use_clamp;        Value
                   inputs Value, Value_001, Value_002
VECT_MATH          operation; inputs Vector, Vector_001, Scale   Vector, Value
INVERT             inputs Fac, Color                             Color
GAMMA              inputs Color, Gamma                           Color
BRIGHTCONTRAST     inputs Color, Bright, Contrast                Color
HUE_SAT            inputs Hue, Saturation, Value, Fac, Color     Color
VALTORGB           positions [..], colors [[r,g,b,a], ..],       Color, Alpha
                   interpolation ('LINEAR'|'CONSTANT'|'EASE'...);
                   input Fac
CURVE_RGB          lut: 256×4 table (C, R, G, B curves sampled   Color
                   on [0, 1]); inputs Fac, Color
RGB_TO_BW          input Color                                   Val
VALUE / RGB        value                                         Value / Color
NORMAL_MAP         space ('TANGENT'|'OBJECT'|'WORLD'),           Normal
                   object_matrix (3×3, OBJECT space only);
                   inputs Strength, Color
BUMP               invert; inputs Strength, Distance, Height,    Normal
                   Normal (height: a value ref the core
                   re-evaluates at offset positions)
LIGHT_PATH         —                                             Is Camera Ray, Is Shadow Ray
                                                                 (evaluated as 1 / 0: see the
                                                                 README; the exporter warns)
=================  ============================================  ==========================

Core semantics the exporter relies on (issue 14, core side; tests/test_shading_*.py)
-------------------------------------------------------------------------------------
* ``<value>`` constants: a number, or a list of 1–4 numbers (colours are RGB: a 4th
  component is ignored). Inputs are read with Blender's implicit conversions (colour →
  float = Rec.709 luminance, vector → float = component average, float → (f, f, f)).
* TEX_IMAGE with no ``Vector`` input reads the active UV map. A ``texture`` row outside
  the table renders magenta (one warning). Cubic / Smart interpolation run as Linear.
* MIX_RGB (the pre-3.4 node: inputs Fac, Color1, Color2; params blend_type,
  use_clamp) is accepted too. Blend modes MIX ADD MULTIPLY SUBTRACT SCREEN DIVIDE
  DIFFERENCE EXCLUSION DARKEN LIGHTEN OVERLAY SOFT_LIGHT LINEAR_LIGHT; others → warning,
  MIX. Unknown MATH / VECT_MATH operations → warning, ADD.
* VALTORGB interpolation CARDINAL / B_SPLINE runs as LINEAR (EASE, CONSTANT exact).
* NORMAL_MAP ``object_matrix`` is the object's world matrix 3×3
  (``matrix_world.to_3x3()``); the core applies its inverse transpose. Without
  ``MeshTable.tangents`` the tangent frame is the triangle's UV gradient ∂p/∂u.
* TEX_COORD: the description has no object transforms, so Object = world position,
  Normal = world shading normal, Generated = world position normalised to the object's
  world-space bounding box (``MeshTable.object_ids``): exact for objects with an identity
  (Object, Normal) or rotation-free (Generated) transform.
* LIGHT_PATH: any output socket name; Is Camera Ray = 1, every other output 0.
* ``bump_shadowing``: with a ``normal`` output, the diffuse lobe's value is multiplied by
  Cycles' bump shadowing term of that model (:mod:`ercuts_core.bump_shadowing`; the exporter
  writes the one of the Blender version); NONE keeps the exact Lambert cosine.
* ``alpha`` output: stochastic transparency for every ray (camera, bounce, shadow).
* ``emission`` output: evaluated per point (radiance = colour × strength, two-sided);
  lights are chosen by each triangle's mean emission over 16 stratified points, so
  emissive textures stay importance-sampled by power.
* A malformed program or an unsupported node type → one warning naming material and node,
  and the whole material uses its ``MaterialTable`` constants.

Geometry the programs read comes from ``MeshTable.uvs`` ((T, 3, 2) per-corner UVs of the
active render UV map; absent → UV (0, 0) as Cycles) and ``MeshTable.tangents`` ((T, 3, 4)
per-corner world-space MikkTSpace tangent xyz and bitangent sign w, from Blender's
``calc_tangents``). Images live once each in ``SceneDescription.textures``
(:class:`ercuts_core.shading.textures.TextureTable`): float32 linear (H, W, 4) RGBA with
straight alpha, row 0 at the image's *bottom* (Blender's pixel order), a name for messages.
"""
