import copy
from pathlib import Path

import numpy as np
import pytest

from symdrive_core.rotations import quat_from_yaw
from symdrive_core.scene import load_manifest
from symdrive_core.scene.poses import Pose

DEMO = Path(__file__).resolve().parents[2] / "symdrive_core" / "data" / "demo_street"


@pytest.fixture(scope="session")
def demo_manifest():
    return load_manifest(DEMO)


@pytest.fixture
def demo(demo_manifest):
    """A fresh copy of the demo street's manifest (tests change its actors)."""
    return copy.deepcopy(demo_manifest)


def park(manifest, actor_id: str, x: float, y: float, yaw: float):
    """Make ``actor_id`` a car parked at (x, y, yaw) in every frame."""
    actor = manifest.actor(actor_id)
    z = 0.5 * float(actor.wlh[2])
    pose = Pose(np.array([x, y, z]), quat_from_yaw(yaw))
    actor.poses = [pose] * len(manifest.frames)
    return actor


def only_actors(manifest, ids):
    manifest.actors = [a for a in manifest.actors if a.id in ids]
    return manifest
