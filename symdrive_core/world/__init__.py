"""The built-in street world: bpy-free helpers to build and read its scene packages.

``scripts/make_world.py`` (inside Blender) generates a package; these modules do the parts
that need only numpy: surface sampling, point-cloud PLY files, projection colouring, and
readers for the package's ``ground_truth`` block.
"""
