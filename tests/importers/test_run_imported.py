"""``symdrive run`` on an imported package: the same stages and numbers as on the native package
with the same content (background, cameras, recorded images, held-out split)."""

from __future__ import annotations

import json
import os
import shutil

import pytest

from symdrive_core.cli import main

from .demo_formats import CAMERA_HEIGHT, DEMO, demo_world, link_images, write_colmap

pytest.importorskip("pycolmap")


def _native(tmp_path):
    """The demo street as the importer would write it, in its own world: background, the front
    camera's frames and images, the held-out split; no actors or effects."""
    pkg = tmp_path / "native"
    data = json.loads((DEMO / "manifest.json").read_text())
    gt = data["ground_truth"]
    data.update(actors=[], masks={}, effects={},
                ground_truth={"camera": gt["camera"], "train_frames": gt["train_frames"],
                              "heldout_frames": gt["heldout_frames"]})
    data["background"] = {"splats": "reconstruction/background.ply"}
    files = ["reconstruction/background.ply"]
    for c in data["cameras"]:
        for f in c["frames"]:
            f.pop("depth", None)
            files.append(f["image"])
    for rel in files:
        (pkg / rel).parent.mkdir(parents=True, exist_ok=True)
        try:
            os.link(DEMO / rel, pkg / rel)
        except OSError:
            shutil.copy2(DEMO / rel, pkg / rel)
    (pkg / "manifest.json").write_text(json.dumps(data))
    return pkg


def _report(pkg):
    assert main(["run", str(pkg)]) == 0
    return json.loads((pkg / "output" / "report.json").read_text())


@pytest.mark.slow  # about 22 s on 2 shared cores
def test_run_on_imported_package_matches_native(tmp_path):
    world = demo_world(seed=21, max_splats=None)
    model = write_colmap(world, tmp_path / "sparse")
    link_images(world, tmp_path / "images")
    from symdrive_core.io.ply import write_splats

    write_splats(tmp_path / "trained.ply", world.splats)
    pkg = tmp_path / "imported"
    assert main(["import", "colmap", str(model), "--images", str(tmp_path / "images"), "--splats",
                 str(tmp_path / "trained.ply"), "--out", str(pkg), "--camera-height", str(CAMERA_HEIGHT),
                 "--heldout-every", "5", "--copy-images"]) == 0
    a, b = _report(_native(tmp_path)), _report(pkg)
    assert [(s["name"], s["ran"]) for s in a["stages"]] == [(s["name"], s["ran"]) for s in b["stages"]]
    ra, rb = a["metrics"]["reconstruction"], b["metrics"]["reconstruction"]
    assert ra["frames"] == rb["frames"] == 6
    assert ra["psnr_heldout"] > 20
    assert abs(ra["psnr_heldout"] - rb["psnr_heldout"]) < 0.05, (ra, rb)
    assert abs(ra["ssim_heldout"] - rb["ssim_heldout"]) < 1e-3, (ra, rb)
