import json

import numpy as np
import pytest

from symdrive_core import conventions
from symdrive_core.scene import load_manifest
from tests.conftest import look_at_c2w

pytestmark = pytest.mark.blender


def _package(tmp_path, width=64, height=48, n=5):
    frames, cams = [], []
    for i in range(n):
        c2w = look_at_c2w((2.0 * i, 1.0, 1.5), (2.0 * i + 10.0, 0.0, 1.0))
        K = conventions.intrinsics(50.0 + i, 55.0 + 1.1 * i, 30.0, 26.0)  # fx != fy, off-centre, zooming
        frames.append({"index": i, "timestamp": 0.1 * i})
        cams.append({"K": K.tolist(), "camera_to_world": c2w.tolist()})
    d = {
        "format": "symdrive-scene",
        "version": 1,
        "name": "drive",
        "frames": frames,
        "cameras": [{"name": "front", "width": width, "height": height, "frames": cams}],
        "effects": {"lateral_offsets": [-2.0, 2.0]},
    }
    (tmp_path / "manifest.json").write_text(json.dumps(d))
    return tmp_path / "manifest.json"


def test_camera_rig_round_trips_through_export(blender, tmp_path):
    source = load_manifest(_package(tmp_path))
    assert blender.ops.symdrive.import_camera_rig(filepath=str(source.path), lateral_offsets="1") == {
        "FINISHED"
    }
    scene = blender.context.scene
    assert (scene.render.resolution_x, scene.render.resolution_y, scene.frame_end) == (64, 48, 5)
    assert scene.render.fps / scene.render.fps_base == pytest.approx(10.0)
    front = blender.data.objects["front"]
    copies = sorted(c.name for c in front.children)
    assert copies == ["front +1 m", "front +2 m", "front -2 m"]
    scene.frame_set(3)
    shifted = blender.data.objects["front +2 m"].matrix_world
    expected = conventions.lateral_shift(source.cameras[0].frames[2].camera_to_world, 2.0)
    np.testing.assert_allclose(conventions.blender_camera_to_opencv(np.array(shifted)), expected, atol=1e-5)

    out = tmp_path / "exported"
    assert blender.ops.symdrive.export_scene(directory=str(out)) == {"FINISHED"}
    m = load_manifest(out)
    assert [c.name for c in m.cameras] == ["front"]  # offset copies are previews, not exported
    assert m.effects.lateral_offsets == [-2.0, 1.0, 2.0]
    for a, b in zip(source.cameras[0].frames, m.cameras[0].frames, strict=True):
        np.testing.assert_allclose(b.K, a.K, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(b.camera_to_world, a.camera_to_world, atol=1e-5)
