"""Where Blender's Python API changed between 4.2 and 5.2: one helper per change.

Each helper detects the feature (an attribute or an enum item) rather than comparing version
numbers, so a Blender that back-ports or drops a feature gets the right branch.
"""

from __future__ import annotations

import bpy


def set_float_exr(image_settings) -> None:
    """Make ``image_settings`` write a single-layer 32-bit float OpenEXR (RGBA).

    Blender 5.0 split the output format into a media type and a file format; the file format's
    items depend on the media type, so the media type is set first where it exists.
    """
    if hasattr(image_settings, "media_type"):
        image_settings.media_type = "IMAGE"
    image_settings.file_format = "OPEN_EXR"
    image_settings.color_mode, image_settings.color_depth = "RGBA", "32"
    if hasattr(image_settings, "exr_codec"):
        image_settings.exr_codec = "ZIP"


def material_node_tree(mat: bpy.types.Material) -> bpy.types.ShaderNodeTree:
    """The node tree of a new material, switching nodes on where that is still a setting (before 5.0,
    a new material has no node tree until ``use_nodes`` is set; from 5.0 it always has one)."""
    if mat.node_tree is None:
        mat.use_nodes = True
    return mat.node_tree


def set_modifier_input(mod: bpy.types.Modifier, identifier: str, value) -> None:
    """Set a Geometry Nodes modifier input by its socket identifier.

    Up to 5.0 the inputs are ID properties of the modifier (``mod["Socket_1"]``); later releases
    expose them as typed properties (``mod.properties.inputs.Socket_1.value``).
    """
    inputs = getattr(getattr(mod, "properties", None), "inputs", None)
    if inputs is not None and hasattr(inputs, identifier):
        getattr(inputs, identifier).value = value
    else:
        mod[identifier] = value


def get_modifier_input(mod: bpy.types.Modifier, identifier: str):
    inputs = getattr(getattr(mod, "properties", None), "inputs", None)
    if inputs is not None and hasattr(inputs, identifier):
        return getattr(inputs, identifier).value
    return mod[identifier]


def action_fcurves(action: bpy.types.Action | None, owner: bpy.types.ID | None = None) -> list:
    """The F-curves of ``action`` that animate ``owner`` (all of them when ``owner`` is None).

    Blender 4.4 made actions layered (layers > strips > channel bags per slot) and 5.0 removed
    the legacy ``Action.fcurves``; a legacy action is read directly.
    """
    if action is None:
        return []
    layers = getattr(action, "layers", None)
    if layers is None:  # 4.2/4.3: a flat list of F-curves
        return list(action.fcurves)
    slot = None
    if owner is not None and owner.animation_data is not None:
        slot = getattr(owner.animation_data, "action_slot", None)
    out = []
    for layer in layers:
        for strip in layer.strips:
            for bag in getattr(strip, "channelbags", ()):
                if slot is None or bag.slot == slot:
                    out.extend(bag.fcurves)
    if not out and not len(layers) and hasattr(action, "fcurves"):  # 4.4/4.5 legacy-mode action
        out = list(action.fcurves)
    return out


def object_fcurves(obj: bpy.types.Object) -> list:
    """F-curves of the action animating ``obj`` (empty when it has none)."""
    anim = obj.animation_data
    return action_fcurves(anim.action if anim is not None else None, obj)
