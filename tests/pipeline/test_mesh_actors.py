"""Mesh-only actors end to end: a GLB car (one the test builds, and a real third-party one) is
sampled into splats, rendered and masked by ``symdrive run``; an actor that cannot be rendered
stops the plan with exit 2 naming it."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from symdrive_core.cli import main
from symdrive_core.io.images import read_image, read_mask
from symdrive_core.io.ply import write_splats
from symdrive_core.pipeline.plan import make_plan
from symdrive_core.pipeline.run import run_scene
from symdrive_core.pipeline.scene_render import SceneRenderer, actor_splats
from symdrive_core.scene import ManifestError, load_manifest
from tests.conftest import manifest_dict
from tests.insertion import synthetic

trimesh = pytest.importorskip("trimesh")

KENNEY = Path(__file__).resolve().parents[1] / "data/meshes/kenney_suv"
PAINT = [0.7, 0.02, 0.02, 1.0]  # linear base colour factor: a red car


def car_glb(path: Path) -> Path:
    """A car-sized two-box car in glTF's frame (+Y up, length along x so it faces +X in the vehicle
    frame after the turn to Z up), origin at the box centre, red body and dark cabin."""
    body = trimesh.creation.box(extents=[4.5, 1.0, 1.8])
    body.apply_translation([0, -0.25, 0])
    cabin = trimesh.creation.box(extents=[2.4, 0.5, 1.6])
    cabin.apply_translation([-0.3, 0.5, 0])
    body.visual = trimesh.visual.TextureVisuals(material=trimesh.visual.material.PBRMaterial(baseColorFactor=PAINT))
    cabin.visual = trimesh.visual.TextureVisuals(
        material=trimesh.visual.material.PBRMaterial(baseColorFactor=[0.03, 0.03, 0.04, 1.0]))
    scene = trimesh.Scene()
    scene.add_geometry(body, node_name="body")
    scene.add_geometry(cabin, node_name="cabin")
    path.write_bytes(scene.export(file_type="glb"))
    return path


def mesh_package(root: Path, n_frames=3) -> Path:
    """The tiny test street with two mesh-only inserted cars: the built GLB 8 m ahead and the Kenney
    toy SUV (0.875 m long, front along glTF +Z, so -Y here: turned to face +X) 4 m ahead."""
    root.mkdir(parents=True)
    d = manifest_dict(n_frames=n_frames, width=64, height=40, actors=("glb_car", "kenney"))
    write_splats(root / "background.ply", synthetic.ground())
    car_glb(root / "car.glb")
    shutil.copytree(KENNEY, root / "kenney")
    glb, kenney = d["actors"]
    glb["assets"] = {"mesh": "car.glb"}
    glb["poses"] = [{"translation": [8.0 + i, -1.0, 0.75], "rotation": [1, 0, 0, 0]} for i in range(n_frames)]
    kenney["assets"] = {"mesh": "kenney/vehicle-suv.glb"}
    kenney.pop("wlh")  # no size given: the plan bounds it by the mesh itself
    quarter = [np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)]  # -Y forward -> +X forward
    kenney["poses"] = [{"translation": [4.0 + i, 0.8, 0.0], "rotation": quarter} for i in range(n_frames)]
    (root / "manifest.json").write_text(json.dumps(d))
    return root / "manifest.json"


def test_run_renders_and_masks_mesh_only_glb_cars(tmp_path):
    path = mesh_package(tmp_path / "pkg")
    out = tmp_path / "out"
    plan = make_plan(load_manifest(path))
    assert plan.stage("render").actors == ["glb_car", "kenney"]
    report = run_scene(path, out, progress=False)
    assert next(s for s in report["stages"] if s["name"] == "render")["frames_rendered"] == 3
    manifest = load_manifest(path)
    empty = SceneRenderer(manifest).render("front", 0, [])  # the street without cars
    rgb = read_image(out / "render/front/000000.png", channels=3)
    for aid in ("glb_car", "kenney"):
        for fi in range(3):
            assert (out / f"masks/front/{aid}/{fi:06d}.png").exists()
        mask = read_mask(out / f"masks/front/{aid}/000000.png")
        covered = mask > 0.5
        assert covered.sum() >= 20, f"{aid} covers {covered.sum()} pixels"
        diff = np.abs(rgb - empty.rgb).max(-1)
        assert np.median(diff[covered]) > 0.05, f"{aid} is not seen in the render"
    red = rgb[read_mask(out / "masks/front/glb_car/000000.png") > 0.9]
    assert np.median(red[:, 0]) > 2 * np.median(red[:, 1])  # the GLB's red base colour reached the render


def test_mesh_samples_are_cached_and_read_back_the_same(tmp_path):
    path = mesh_package(tmp_path / "pkg", n_frames=1)
    manifest = load_manifest(path)
    cache = tmp_path / "cache"
    first = SceneRenderer(manifest, asset_cache=cache).render("front", 0)
    written = sorted(cache.glob("mesh_splats/*.ply"))
    assert [p.name.split(".")[0] for p in written] == ["glb_car", "kenney"]
    stamps = [p.stat().st_mtime_ns for p in written]
    again = SceneRenderer(manifest, asset_cache=cache).render("front", 0)
    assert [p.stat().st_mtime_ns for p in written] == stamps  # read back, not sampled again
    np.testing.assert_allclose(again.rgb, first.rgb, atol=1e-6)
    in_memory = SceneRenderer(manifest).render("front", 0)
    np.testing.assert_allclose(in_memory.rgb, first.rgb, atol=1e-6)
    car_glb(tmp_path / "pkg/car.glb")  # same content: same key
    glb = manifest.actor("glb_car")
    actor_splats(manifest, glb, cache)
    assert len(list(cache.glob("mesh_splats/glb_car.*.ply"))) == 1
    (tmp_path / "pkg/car.glb").write_bytes(trimesh.Scene(trimesh.creation.box()).export(file_type="glb"))
    assert len(actor_splats(manifest, glb, cache)) == 12000
    assert len(list(cache.glob("mesh_splats/glb_car.*.ply"))) == 2  # a changed mesh is sampled anew


def test_mesh_only_cars_cast_shadows_like_splat_cars(tmp_path):
    path = mesh_package(tmp_path / "pkg", n_frames=1)
    d = json.loads(path.read_text())
    d["effects"].update({"shadows": True, "sun_direction": [-0.4, 0.5, -0.75]})
    path.write_text(json.dumps(d))
    stage = make_plan(load_manifest(path)).stage("cast_shadow")
    assert stage.run and stage.actors == ["glb_car"]  # the one with a size


@pytest.mark.parametrize("assets, write, words", [
    ({"mesh": "bad.fbx"}, b"Kaydara FBX Binary  \x00", "FBX is not read here"),
    ({"mesh": "bad.glb"}, b"glTF\x02\x00\x00\x00 broken", "cannot read GLB"),
    ({"mesh": "missing.glb"}, None, "mesh 'missing.glb' not found"),
    ({"splats": "bad.ply", "mesh": "car.glb"}, b"not a ply", "splat file 'bad.ply' cannot be read"),
])
def test_an_actor_that_cannot_be_rendered_stops_the_plan(tmp_path, capsys, assets, write, words):
    root = tmp_path / "pkg"
    path = mesh_package(root, n_frames=1)
    d = json.loads(path.read_text())
    d["actors"][1]["assets"] = assets
    path.write_text(json.dumps(d))
    name = assets.get("splats") or assets["mesh"]
    if write is not None:
        (root / name).write_bytes(write)
    with pytest.raises(ManifestError) as exc:
        make_plan(load_manifest(path))
    assert exc.value.field == "actors[1].assets" and "'kenney'" in str(exc.value) and words in str(exc.value)
    assert main(["plan", str(path)]) == 2
    err = capsys.readouterr().err
    assert "manifest.json" in err and "actors[1].assets" in err and "kenney" in err and words in err
    if write is not None:  # (a missing file is refused earlier, by the file check, naming the field too)
        assert main(["run", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 2
        assert "actors[1].assets" in capsys.readouterr().err
        assert not (tmp_path / "out" / "report.json").exists()
