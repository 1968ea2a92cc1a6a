"""Closed-loop simulation: an agent drives the ego car through a scene package.

``SymDriveEnv`` (Gymnasium API) renders the package's cameras rigidly attached to the ego, moves
the ego by a kinematic bicycle model, keeps traffic on its recorded poses (or SUMO in lock-step),
ends episodes on collision, leaving the road, the route's end or a time limit, and scores them as
NAVSIM's PDM score does (:mod:`.scores`). Views off the recorded path are raw 3DGS, or with
``restore=True`` go through the restorer online (:mod:`.restore`). Heavy imports (torch, gymnasium, imageio) happen inside.
"""

from .config import SimConfig

__all__ = ["SimConfig", "SymDriveEnv"]

try:  # Gymnasium comes with the "sim" extra; SimConfig alone does not need it
    from gymnasium.envs.registration import register
except ImportError:
    pass
else:
    # gymnasium.make("SymDrive-v0", ...) after importing this package, or
    # gymnasium.make("symdrive_core.sim:SymDrive-v0", ...), which imports it.
    register(id="SymDrive-v0", entry_point="symdrive_core.sim.env:SymDriveEnv")


def __getattr__(name):
    if name == "SymDriveEnv":
        from .env import SymDriveEnv

        return SymDriveEnv
    raise AttributeError(name)
