"""Optional denoising with OpenImageDenoise through Blender's compositor.

Ercuts does not denoise itself. With ``scene.ercuts.use_denoising`` on, the engine
writes the denoiser's guides (Normal, Albedo) and keeps the noisy image as the
"Noisy Image" pass (:mod:`.passes`); :func:`setup_compositor` (operator
``ercuts.setup_denoising``) builds Render Layers → Denoise (Image, Normal, Albedo) →
composite output, so the saved composite is denoised while the render layer's Combined
and Noisy Image stay noisy. The compositor API differs between 3.x and 5.0
(``compat.compositor_tree`` / ``compat.compositor_output_socket``). A Blender built
without OpenImageDenoise (Debian's 3.4.1) passes the image through the Denoise node
unchanged: :func:`setup_compositor` and the engine warn about it.
"""
from __future__ import annotations

import bpy

from . import compat

DENOISE_NODE_NAME = "Ercuts Denoise"
NO_OIDN_WARNING = ("this Blender was built without OpenImageDenoise: the compositor's Denoise "
                   "node passes the image through unchanged")


def _render_layers_node(tree, scene):
    node = next((n for n in tree.nodes if n.bl_idname == "CompositorNodeRLayers"), None)
    if node is None:
        node = tree.nodes.new("CompositorNodeRLayers")
        node.scene = scene
    return node


def setup_compositor(scene) -> list[str]:
    """Turn denoising on and wire Render Layers → Denoise → composite; returns warnings.

    Re-running replaces the links of the existing "Ercuts Denoise" node; other nodes of
    the tree are left alone.
    """
    warnings = []
    scene.ercuts.use_denoising = True
    for view_layer in scene.view_layers:
        view_layer.update_render_passes()  # Normal/Albedo sockets on the Render Layers node
    tree = compat.compositor_tree(scene, create=True)
    layers = _render_layers_node(tree, scene)
    denoise = tree.nodes.get(DENOISE_NODE_NAME)
    if denoise is None:
        denoise = tree.nodes.new("CompositorNodeDenoise")
        denoise.name = denoise.label = DENOISE_NODE_NAME
    denoise.location = (layers.location.x + 300, layers.location.y)
    for name in ("Image", "Normal", "Albedo"):
        output = layers.outputs.get(name)
        if output is None:
            warnings.append(f"the Render Layers node has no {name!r} output "
                            "(is Ercuts the render engine?)")
            continue
        tree.links.new(output, denoise.inputs[name])
    tree.links.new(denoise.outputs["Image"], compat.compositor_output_socket(tree))
    scene.render.use_compositing = True
    if not compat.oidn_available():
        warnings.append(NO_OIDN_WARNING)
    return warnings


class ERCUTS_OT_setup_denoising(bpy.types.Operator):
    """Denoise the render with OpenImageDenoise: add a Denoise node to the compositor, fed by the Normal and Albedo passes"""

    bl_idname = "ercuts.setup_denoising"
    bl_label = "Set Up Denoising"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        for warning in setup_compositor(context.scene):
            self.report({"WARNING"}, f"Ercuts: {warning}")
        return {"FINISHED"}


classes = (ERCUTS_OT_setup_denoising,)

register, unregister = bpy.utils.register_classes_factory(classes)
