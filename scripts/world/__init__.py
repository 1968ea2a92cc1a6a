"""Building blocks of ``scripts/make_world.py``: the procedural street in Blender (bpy).

Run only inside Blender's Python (the ``bpy`` wheel); the bpy-free readers of what these
modules write live in ``symdrive_core.world``.
"""
