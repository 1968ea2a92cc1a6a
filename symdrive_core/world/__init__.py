"""The built-in street world: bpy-free helpers ``scripts/make_world.py`` uses to build its scene
package (an OBJ writer for the assets, projection colouring of the SfM-like points). The library
itself never imports this package; it reads ground truth through :mod:`symdrive_core.scene.ground_truth`.
"""
