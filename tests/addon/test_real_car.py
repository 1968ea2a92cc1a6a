"""Cars the project did not make go the whole way: imported with the size warning, fitted to car
size with one action, exported as a mesh-only actor, and rendered and masked by ``symdrive run``.
Kenney's CC0 toy SUV is a textured multi-node GLB, +Y up and 0.875 m long; the WTFPL voxel car is
a MagicaVoxel OBJ, +Y up, 27 units long, naming a material library it does not ship."""

import json
from pathlib import Path

import numpy as np
import pytest

from tests.addon.scenes import add_camera
from tests.conftest import random_gaussians

pytestmark = pytest.mark.blender
MESHES = Path(__file__).resolve().parents[1] / "data" / "meshes"
CARS = {  # file, import options (the user's choices in the import dialog), length before fitting
    "glb": (MESHES / "kenney_suv" / "vehicle-suv.glb", {}, (0.5, 1.5)),
    "obj": (MESHES / "voxel_car" / "car.obj", {"up_axis": "Y", "forward_axis": "Z"}, (20.0, 40.0)),
}


@pytest.mark.parametrize("kind", sorted(CARS))
def test_a_downloaded_car_imports_fits_exports_and_renders(blender, tmp_path, capsys, kind):
    pytest.importorskip("torch")  # the backend run at the end
    from symdrive_core.cli import main
    from symdrive_core.io.images import read_image, read_mask
    from symdrive_core.io.ply import write_splats

    scene = blender.context.scene
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 64, 40, 100
    scene.render.fps, scene.frame_start, scene.frame_end = 10, 1, 2
    bg = tmp_path / "street" / "background.ply"
    bg.parent.mkdir()
    write_splats(bg, random_gaussians(300, 0, 1, (20.0, 0.0, 1.0), 4.0))
    blender.ops.symdrive.import_splats(filepath=str(bg))

    scene.cursor.location = (9.0, 0.5, 0.0)
    path, options, (lo, hi) = CARS[kind]
    assert blender.ops.symdrive.import_vehicle(filepath=str(path), **options) == {"FINISHED"}
    root = blender.context.active_object
    said = capsys.readouterr()
    assert "Not car-sized" in said.out + said.err and lo < root.symdrive.wlh[1] < hi  # warned
    assert blender.ops.symdrive.fit_vehicle_size(length=4.6) == {"FINISHED"}  # the user's one action
    w, l, h = root.symdrive.wlh
    # Upright and car-sized (toys: wide and tall for their length), not on end or on its side.
    assert l == pytest.approx(4.6, rel=1e-3) and 1.2 < w < 4.0 and 1.0 < h < 3.5 and h < l and w < l

    cam = add_camera(blender, shift=(0.0, 0.0))
    cam.location = (0.0, 0.5, 1.6)
    scene.camera = cam
    out = tmp_path / "package"
    assert blender.ops.symdrive.export_scene(directory=str(out)) == {"FINISHED"}
    manifest = json.loads((out / "manifest.json").read_text())
    actor = manifest["actors"][0]
    assert actor["assets"]["splats"] is None and actor["assets"]["mesh"].endswith(".glb")

    run = tmp_path / "run"
    assert main(["run", str(out), "--out", str(run), "--quiet", "--allow-external-assets"]) == 0
    aid = actor["id"]
    mask = read_mask(run / f"masks/front/{aid}/000000.png")
    assert mask.mean() > 0.02  # the car covers part of the view
    car = mask > 0.5
    rgb = read_image(run / "render/front/000000.png", channels=3)
    empty = tmp_path / "empty"
    del manifest["actors"][0]
    manifest["masks"] = {"entries": [], "id_maps": []}
    (out / "manifest.json").write_text(json.dumps(manifest))
    assert main(["run", str(out), "--out", str(empty), "--quiet", "--allow-external-assets"]) == 0
    street = read_image(empty / "render/front/000000.png", channels=3)
    assert np.abs(rgb[car] - street[car]).mean() > 0.05  # the car's pixels are the car's, not the street's
