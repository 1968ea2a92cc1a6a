"""Online restoration of off-path views: loaded only when asked, applied only off the path."""

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np

from symdrive_core.sim import SimConfig, SymDriveEnv

TINY = dict(image_size=(32, 18), time_limit_s=3.0)
ROOT = Path(__file__).resolve().parents[2]


def drive(env, steer=0.25, steps=7):
    """Straight for two steps, then steering off the path; (observation, off path) per step."""
    obs, _ = env.reset(seed=0)
    out = [(obs["images"]["front"], env.off_path())]
    for k in range(steps):
        obs, *_ = env.step([0.0, 0.0 if k < 2 else steer])
        out.append((obs["images"]["front"], env.off_path()))
        if env.end_reason is not None:
            break
    return out


def test_restore_changes_only_off_path_views(demo):
    raw = drive(SymDriveEnv(demo, SimConfig(**TINY)))
    env = SymDriveEnv(demo, SimConfig(restore=True, **TINY))
    restored = drive(env)
    assert len(raw) == len(restored)
    flags = [off for _, off in restored]
    assert not flags[0] and any(flags), flags
    for (a, off), (b, _) in zip(raw, restored):
        if off:
            assert np.abs(a.astype(int) - b.astype(int)).mean() > 0.5
        else:
            assert np.array_equal(a, b)
    # Cached per (frame, camera, rounded offset): a second episode samples nothing new.
    n = env.restorer.samples
    assert n > 0 and env.timing["restore"] > 0
    drive(env)
    assert env.restorer.samples == n


def test_place_is_the_nearest_frame_and_its_lateral_offset(demo):
    from symdrive_core import conventions
    from symdrive_core.sim.restore import OnlineRestorer

    env = SymDriveEnv(demo, SimConfig(restore=True, **TINY))
    r = OnlineRestorer(env)
    c2w = demo.camera("front").frames[4].camera_to_world
    assert r.place("front", c2w) == (4, 0.0)
    assert r.place("front", conventions.lateral_shift(c2w, -0.8)) == (4, -0.75)  # rounded to 0.25 m


SCRIPT = textwrap.dedent("""
    import json, sys
    from symdrive_core.scene import load_manifest
    from symdrive_core.sim import SimConfig, SymDriveEnv
    env = SymDriveEnv(load_manifest(sys.argv[1]), SimConfig(restore=sys.argv[2] == "1", image_size=(16, 10)))
    env.reset(seed=0)
    seen = []
    for k in range(int(sys.argv[3])):
        env.step([0.0, 0.0 if k < 2 else 0.25])
        seen.append([env.off_path(), "symdrive_core.diffusion.models" in sys.modules])
    print(json.dumps(seen))
""")


def _run(restore: str, steps: int) -> list:
    from .conftest import DEMO

    out = subprocess.run([sys.executable, "-c", SCRIPT, str(DEMO), restore, str(steps)], cwd=ROOT,
                         capture_output=True, text=True, timeout=300, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_no_diffusion_model_without_restore():
    seen = _run("0", 6)
    assert seen[-1][0] and not any(models for _, models in seen)
    # With restore=True the model is loaded at the first off-path view, not before.
    seen = _run("1", 6)
    assert seen[-1][0] and all(off == models for off, models in seen), seen
