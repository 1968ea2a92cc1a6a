"""The background frame: scene packages express every pose relative to the background splats."""

from __future__ import annotations

import bpy
import numpy as np
from mathutils import Matrix

from .core import errors


def background_matrix(scene: bpy.types.Scene, depsgraph=None) -> Matrix:
    """World matrix of the background splat object (identity when there is none), as ``depsgraph``
    evaluates it where given (a scene other than the window's has no other up-to-date one).

    It must be rigid: the backend renders the background PLY unscaled, so a scaled background
    object would make every exported pose disagree with what the artist sees.
    """
    bg = scene.symdrive.background
    if bg is None or bg.name not in scene.objects:
        return Matrix.Identity(4)
    M = (bg if depsgraph is None else bg.evaluated_get(depsgraph)).matrix_world.copy()
    scale = np.array(M.to_scale())
    if not np.allclose(scale, 1.0, atol=1e-5):
        raise errors.InputError(
            bg.name,
            f"background object is scaled by {tuple(np.round(scale, 5))}; "
            "apply the scale to the splats instead (poses must stay rigid)",
            "scale",
        )
    return M


def rigid(M: Matrix) -> np.ndarray:
    """4x4 numpy matrix with rotation re-orthonormalised and scale removed."""
    loc, rot, _ = M.decompose()
    out = np.eye(4)
    out[:3, :3] = np.array(rot.to_matrix())
    out[:3, 3] = np.array(loc)
    return out


def world_to_basis(obj: bpy.types.Object, world: Matrix) -> Matrix:
    """The ``matrix_basis`` that puts ``obj`` at ``world`` given its (current) parent."""
    if obj.parent is None:
        return world
    return (obj.parent.matrix_world @ obj.matrix_parent_inverse).inverted() @ world
