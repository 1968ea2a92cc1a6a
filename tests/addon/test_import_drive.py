"""Import Recorded Drive: nerfstudio transforms.json, 3DGS cameras.json and COLMAP models become
animated cameras with the recorded frames as their backgrounds."""

import json
import struct
import sys
import zlib

import numpy as np
import pytest

from symdrive_core import conventions
from tests.conftest import look_at_c2w

pytestmark = pytest.mark.blender

W, H, N = 40, 30, 4
GL_TO_CV = np.diag([1.0, -1.0, -1.0, 1.0])


def _png(path, value):
    """A tiny grey PNG (no image library needed)."""
    raw = b"".join(b"\x00" + bytes([value]) * (W * 3) for _ in range(H))

    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", W, H, 8, 2, 0, 0, 0))
                     + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


def _poses():
    return [look_at_c2w((1.5 * i, 0.5, 1.6), (1.5 * i + 10.0, 0.0, 1.2)) for i in range(N)]


def _nerfstudio(tmp_path):
    frames = []
    for i, c2w in enumerate(_poses()):
        _png(tmp_path / "images" / f"frame_{i:05d}.png", 40 * i)
        frames.append({"file_path": f"images/frame_{i:05d}.png", "transform_matrix": (c2w @ GL_TO_CV).tolist()})
    d = {"camera_model": "OPENCV", "fl_x": 36.0, "fl_y": 36.0, "cx": 22.0, "cy": 14.0, "w": W, "h": H,
         "frames": frames}
    (tmp_path / "transforms.json").write_text(json.dumps(d))
    return tmp_path / "transforms.json"


def _gs(tmp_path):
    cams = []
    for i, c2w in enumerate(_poses()):
        _png(tmp_path / "images" / f"{i:04d}.png", 40 * i)
        cams.append({"id": i, "img_name": f"{i:04d}", "width": W, "height": H, "position": c2w[:3, 3].tolist(),
                     "rotation": c2w[:3, :3].tolist(), "fx": 30.0, "fy": 30.0})
    (tmp_path / "cameras.json").write_text(json.dumps(cams))
    return tmp_path / "cameras.json"


COLMAP_K = conventions.intrinsics(32.0, 33.0, 21.0, 15.5)


def colmap_drive(tmp_path):
    """A binary COLMAP model in sparse/0 with its images in images/, as ``colmap mapper`` leaves them."""
    from tests.importers.demo_formats import World, write_colmap

    names = [f"{i:04d}.png" for i in range(N)]
    for i, name in enumerate(names):
        _png(tmp_path / "images" / name, 40 * i)
    world = World(S=np.eye(4), names=names, images=[], K=COLMAP_K, width=W, height=H, c2w=np.stack(_poses()),
                  c2w_demo=np.stack(_poses()), splats=None, points=np.zeros((0, 3)), colors=np.zeros((0, 3)))
    return write_colmap(world, tmp_path / "sparse" / "0", with_points=False)


def _check(bpy, K):
    scene = bpy.context.scene
    cams = [o for o in bpy.data.objects if o.type == "CAMERA"]
    assert [c.name for c in cams] == ["front"] and scene.camera == cams[0]
    cam = cams[0]
    assert (scene.render.resolution_x, scene.render.resolution_y) == (W, H)
    assert scene.frame_end - scene.frame_start + 1 == N
    for i, c2w in enumerate(_poses()):
        scene.frame_set(scene.frame_start + i)
        got = conventions.blender_camera_to_opencv(np.array(cam.matrix_world))
        np.testing.assert_allclose(got, c2w, atol=1e-5)
    lens = conventions.lens_from_intrinsics(K, W, H)
    assert cam.data.lens == pytest.approx(lens.lens_mm, rel=1e-5)
    assert cam.data.shift_x == pytest.approx(lens.shift_x, abs=1e-6)
    assert cam.data.shift_y == pytest.approx(lens.shift_y, abs=1e-6)
    bgs = cam.data.background_images
    assert cam.data.show_background_images and len(bgs) == N
    for i in range(N):  # on frame i only background i shows
        scene.frame_set(scene.frame_start + i)
        assert [round(b.alpha, 6) for b in bgs] == [1.0 if j == i else 0.0 for j in range(N)]
    return [b.image.filepath for b in bgs]


def test_nerfstudio_transforms_become_animated_cameras_with_backgrounds(blender, tmp_path):
    path = _nerfstudio(tmp_path)
    assert blender.ops.symdrive.import_drive(filepath=str(path)) == {"FINISHED"}
    files = _check(blender, conventions.intrinsics(36.0, 36.0, 22.0, 14.0))
    assert [f.replace("\\", "/").rsplit("/", 1)[-1] for f in files] == [f"frame_{i:05d}.png" for i in range(N)]


def test_3dgs_cameras_json_becomes_animated_cameras_with_backgrounds(blender, tmp_path):
    path = _gs(tmp_path)
    assert blender.ops.symdrive.import_drive(filepath=str(path)) == {"FINISHED"}
    files = _check(blender, conventions.intrinsics(30.0, 30.0, W / 2.0, H / 2.0))
    assert [f.replace("\\", "/").rsplit("/", 1)[-1] for f in files] == [f"{i:04d}.png" for i in range(N)]


@pytest.mark.parametrize("pick", ["folder", "images.bin"])
def test_colmap_model_becomes_animated_cameras_with_the_core_importers_poses(blender, tmp_path, pick):
    pytest.importorskip("pycolmap")
    from symdrive_core.importers.colmap import read_colmap

    model = colmap_drive(tmp_path)
    path = model if pick == "folder" else model / pick
    assert blender.ops.symdrive.import_drive(filepath=str(path)) == {"FINISHED"}
    files = _check(blender, COLMAP_K)
    assert [f.replace("\\", "/").rsplit("/", 1)[-1] for f in files] == [f"{i:04d}.png" for i in range(N)]
    cam = blender.data.objects["front"]
    scene = blender.context.scene
    for i, view in enumerate(read_colmap(model, tmp_path / "images").grouped.table[0]):
        scene.frame_set(scene.frame_start + i)
        got = conventions.blender_camera_to_opencv(np.array(cam.matrix_world))
        np.testing.assert_allclose(got, view.c2w, atol=1e-5)


def test_colmap_without_pycolmap_is_one_line_saying_how_to_install_it(blender, tmp_path, monkeypatch):
    pytest.importorskip("pycolmap")  # to write the model
    model = colmap_drive(tmp_path)
    monkeypatch.setitem(sys.modules, "pycolmap", None)  # `import pycolmap` now raises ImportError
    with pytest.raises(RuntimeError) as raised:
        blender.ops.symdrive.import_drive(filepath=str(model))
    message = str(raised.value).strip()
    assert len(message.splitlines()) == 1 and "Traceback" not in message, message
    assert f'"{sys.executable}" -m pip install pycolmap' in message
    assert not [o for o in blender.data.objects if o.type == "CAMERA"]
    assert not blender.data.images


def test_a_json_of_another_kind_is_refused(blender, tmp_path):
    (tmp_path / "x.json").write_text('{"hello": 1}')
    with pytest.raises(RuntimeError, match="COLMAP choose the model folder"):
        blender.ops.symdrive.import_drive(filepath=str(tmp_path / "x.json"))
    assert not [o for o in blender.data.objects if o.type == "CAMERA"]
