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
from tests.addon.test_import_drive import colmap_drive
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
zip_path, cloud, car, package, colmap_model = sys.argv[1:6]
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
    assert bpy.ops.symdrive.import_drive(filepath=colmap_model) == {'FINISHED'}  # vendored importers.colmap
    assert bpy.data.objects['front'].type == 'CAMERA'
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
    pytest.importorskip("pycolmap")
    colmap_model = colmap_drive(tmp_path / "colmap")
    env = {**os.environ, "BLENDER_USER_RESOURCES": str(tmp_path / "user")}  # never the real user's folder
    done = subprocess.run(
        [sys.executable, "-c", INSTALL_AND_USE, str(out), str(cloud), str(car), str(tmp_path / "pkg"),
         str(colmap_model)],
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


FAKE_WHEELS = [
    "pycolmap-4.2.1-cp311-cp311-manylinux_2_27_x86_64.manylinux_2_28_x86_64.whl",
    "pycolmap-4.2.1-cp311-cp311-macosx_14_0_arm64.whl",
    "pycolmap-4.2.1-cp311-cp311-win_amd64.whl",
]


def _fake_wheels(folder: Path) -> Path:
    """Tiny stand-ins with real wheel file names (zip files holding one module)."""
    folder.mkdir(parents=True)
    for name in FAKE_WHEELS:
        with zipfile.ZipFile(folder / name, "w") as zf:
            zf.writestr("pycolmap/__init__.py", "")
    return folder


def _build(*args: str):
    return subprocess.run([sys.executable, str(REPO / "scripts" / "build_addon"), *args], capture_output=True,
                          text=True, timeout=120, check=False)


def test_wheels_are_bundled_and_listed_in_the_manifest_with_their_platforms(tmp_path):
    wheels = _fake_wheels(tmp_path / "wheels")
    out = tmp_path / "addon.zip"
    done = _build("--out", str(out), "--wheels", str(wheels))
    assert done.returncode == 0, done.stderr
    with zipfile.ZipFile(out) as zf:
        names = set(zf.namelist())
        manifest = tomllib.loads(zf.read("symdrive/blender_manifest.toml").decode())
        for name in FAKE_WHEELS:  # bundled byte for byte
            assert zf.read(f"symdrive/wheels/{name}") == (wheels / name).read_bytes()
    assert manifest["wheels"] == [f"./wheels/{n}" for n in sorted(FAKE_WHEELS)]
    assert manifest["platforms"] == ["linux-x64", "macos-arm64", "windows-x64"]
    assert manifest["id"] == "symdrive" and manifest["permissions"]["files"]  # the rest is untouched
    assert "symdrive/vendor/symdrive_core/importers/colmap.py" in names


@pytest.mark.parametrize(("wheel", "needle"), [(None, "no .whl files"), ("pycolmap-1.0.whl", "not a wheel file name"),
                                               ("pycolmap-1.0-cp311-cp311-win32.whl", "'win32'")])
def test_a_wheels_folder_blender_cannot_use_is_refused_in_one_line(tmp_path, wheel, needle):
    folder = tmp_path / "wheels"
    folder.mkdir()
    if wheel:
        (folder / wheel).write_bytes(b"PK")
    out = tmp_path / "addon.zip"
    done = _build("--out", str(out), "--wheels", str(folder))
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert needle in done.stderr and "--wheels" in done.stderr
    assert not list(tmp_path.glob("*.zip")) and not list(tmp_path.glob(".addon*"))


@pytest.mark.blender
def test_blenders_validator_accepts_the_zip_with_wheels(tmp_path):
    bpy_spec = pytest.importorskip("bpy").__spec__
    out = tmp_path / "addon.zip"
    assert _build("--out", str(out), "--wheels", str(_fake_wheels(tmp_path / "wheels"))).returncode == 0
    validator = next(Path(bpy_spec.origin).parent.glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
    checked = subprocess.run([sys.executable, str(validator), "validate", str(out)], capture_output=True, text=True,
                             timeout=120, check=False)
    assert checked.returncode == 0 and "Success" in checked.stdout, checked.stdout + checked.stderr
