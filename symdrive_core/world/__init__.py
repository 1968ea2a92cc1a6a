"""The built-in street world: bpy-free helpers ``scripts/make_world.py`` uses to build its scene
package (an OBJ writer for the assets, projection colouring of the SfM-like points), and
``symdrive demo``, the run of the whole pipeline on the shipped package (:mod:`.demo`). The
library below the command line never imports this package; it reads ground truth through
:mod:`symdrive_core.scene.ground_truth`.
"""
