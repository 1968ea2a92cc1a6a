"""Where Blender's Python API changed between 4.2 and 5.2, for the world generator.

Each helper detects the feature (an attribute or an enum item) rather than comparing version
numbers, so a Blender that back-ports or drops a feature gets the right branch. On 4.x every
helper does exactly what the generator did before, so 4.x renders are unchanged.
"""

from __future__ import annotations


def set_multilayer_exr(image_settings) -> None:
    """Make ``image_settings`` write one multilayer OpenEXR with every render pass, 32-bit float.

    Up to 4.5 that is the file format ``OPEN_EXR_MULTILAYER``. Blender 5.0 split the output into a
    media type and a file format whose items depend on it: the multilayer EXR is the media type
    ``MULTI_LAYER_IMAGE`` (file format ``OPEN_EXR_MULTILAYER``, or ``OPEN_EXR`` where a release
    names it so), and the media type must be set first.
    """
    if hasattr(image_settings, "media_type"):
        image_settings.media_type = "MULTI_LAYER_IMAGE"
        if image_settings.file_format not in ("OPEN_EXR_MULTILAYER", "OPEN_EXR"):
            try:
                image_settings.file_format = "OPEN_EXR_MULTILAYER"
            except TypeError:
                image_settings.file_format = "OPEN_EXR"
    else:
        image_settings.file_format = "OPEN_EXR_MULTILAYER"
    image_settings.color_depth = "32"
    if hasattr(image_settings, "exr_codec"):
        image_settings.exr_codec = "ZIP"


def node_tree(idblock):
    """The node tree of a new material or world, switching nodes on where that is still a setting
    (before 5.0 a new material or world has no node tree until ``use_nodes`` is set; from 5.0 it
    always has one and ``use_nodes`` is deprecated)."""
    if idblock.node_tree is None:
        idblock.use_nodes = True
    return idblock.node_tree


def set_single_scattering_sky(sky, dust_density: float) -> None:
    """Make a Sky Texture node the single-scattering (Nishita) sky with the given dust/aerosol
    density. Blender 5.0 renamed ``NISHITA`` to ``SINGLE_SCATTERING`` (and added a multiple
    scattering model) and ``dust_density`` to ``aerosol_density``."""
    items = [e.identifier for e in sky.bl_rna.properties["sky_type"].enum_items]
    sky.sky_type = "NISHITA" if "NISHITA" in items else "SINGLE_SCATTERING"
    if hasattr(sky, "dust_density"):
        sky.dust_density = dust_density
    else:
        sky.aerosol_density = dust_density
