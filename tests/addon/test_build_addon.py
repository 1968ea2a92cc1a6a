"""The installable zip: Blender validates and installs it as an extension, which then works in a
Blender whose Python has no symdrive_core (the vendored copy is used)."""

import os
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

from symdrive_core.io.ply import write_splats
from tests.addon.assets import write_car
from tests.conftest import random_gaussians

REPO = Path(__file__).resolve().parents[2]

INSTALL_AND_USE = """
import sys
class _HideInstalledCore:
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in {'symdrive_core', 'torch'}:
            raise ImportError(name + ' is hidden: the add-on must use its vendored copy')
sys.meta_path.insert(0, _HideInstalledCore())
import bpy
import addon_utils
zip_path, cloud, car, package = sys.argv[1:5]
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.context.preferences.system.use_online_access = False
assert bpy.ops.extensions.package_install_files(filepath=zip_path, repo='user_default',
                                                enable_on_install=True) == {'FINISHED'}
module = sys.modules['bl_ext.user_default.symdrive']
assert module.core.CORE == 'bl_ext.user_default.symdrive.vendor.symdrive_core', module.core.CORE
try:
    bpy.ops.symdrive.import_splats(filepath=cloud)
    bpy.context.scene.cursor.location = (8.0, 0.0, 0.0)
    bpy.ops.symdrive.import_vehicle(filepath=car)
    cam = bpy.data.objects.new('cam', bpy.data.cameras.new('cam'))
    bpy.context.scene.collection.objects.link(cam)
    cam.rotation_euler = (1.5708, 0.0, -1.5708)
    cam.location = (0.0, 0.0, 1.0)
    bpy.context.scene.render.resolution_x, bpy.context.scene.render.resolution_y = 32, 24
    bpy.context.scene.frame_end = 2
    bpy.ops.symdrive.export_scene(directory=package)
    assert 'torch' not in sys.modules
finally:
    addon_utils.disable('bl_ext.user_default.symdrive')
print('installed extension ok')
"""


def test_zip_has_the_extension_manifest_and_the_numpy_only_core(tmp_path):
    out = tmp_path / "addon.zip"
    done = subprocess.run(
        [sys.executable, str(REPO / "scripts" / "build_addon"), "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    with zipfile.ZipFile(out) as zf:
        names = set(zf.namelist())
        manifest = tomllib.loads(zf.read("symdrive/blender_manifest.toml").decode())
    assert manifest["id"] == "symdrive" and manifest["type"] == "add-on"
    assert manifest["blender_version_min"] >= "4.2.0"
    for required in (
        "symdrive/__init__.py",
        "symdrive/operators/export_scene.py",
        "symdrive/vendor/symdrive_core/io/ply.py",
        "symdrive/vendor/symdrive_core/scene/manifest.py",
        "symdrive/vendor/symdrive_core/scene/manifest.schema.json",
    ):
        assert required in names
    heavy = [
        n for n in names if any(k in n for k in ("/splat/", "/diffusion/", "/optim/", "/pipeline/", "/cli/"))
    ]
    assert heavy == [] and not any(n.endswith(".pyc") for n in names)


@pytest.mark.blender
def test_blender_installs_the_zip_as_an_extension_that_runs_without_the_installed_core(tmp_path):
    bpy_spec = pytest.importorskip("bpy").__spec__
    out = tmp_path / "addon.zip"
    subprocess.run(
        [sys.executable, str(REPO / "scripts" / "build_addon"), "--out", str(out)],
        check=True,
        capture_output=True,
        timeout=120,
    )
    # Blender's own extension validator accepts the zip
    validator = next(Path(bpy_spec.origin).parent.glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
    checked = subprocess.run(
        [sys.executable, str(validator), "validate", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert checked.returncode == 0 and "Success" in checked.stdout, checked.stdout + checked.stderr
    cloud = tmp_path / "cloud.ply"
    write_splats(cloud, random_gaussians(100, degree=3))
    _, car = write_car(tmp_path / "car", "car")
    env = {**os.environ, "BLENDER_USER_RESOURCES": str(tmp_path / "user")}  # never the real user's folder
    done = subprocess.run(
        [sys.executable, "-c", INSTALL_AND_USE, str(out), str(cloud), str(car), str(tmp_path / "pkg")],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=tmp_path,
        env=env,
        check=False,
    )
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-3000:]
    assert "installed extension ok" in done.stdout
    assert (
        tmp_path / "user" / "extensions" / "user_default" / "symdrive" / "blender_manifest.toml"
    ).is_file()
    assert (tmp_path / "pkg" / "manifest.json").is_file()
