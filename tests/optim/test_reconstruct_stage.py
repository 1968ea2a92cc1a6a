"""``symdrive run`` on a package with images and points but no splats: the reconstruct stage fits
the background into the run's output, later stages use it, and the package's manifest (file and
object) stays as given."""

import json

from symdrive_core.io.images import read_image
from symdrive_core.io.ply import write_splats
from symdrive_core.optim import reconstruct as reconstruct_module
from symdrive_core.optim.reconstruct import ReconstructResult
from symdrive_core.pipeline.run import run_scene
from symdrive_core.pipeline.stages import StageResult, merge_metrics
from symdrive_core.scene import load_manifest

from .conftest import true_scene


def test_reconstruct_stage_hands_its_result_on_without_editing_the_manifest(synthetic_package, tmp_path,
                                                                             monkeypatch):
    root, _ = synthetic_package
    before = (root / "manifest.json").read_text()
    fitted = true_scene()

    def fake_reconstruct(manifest, out, *args, **kwargs):  # the stage's plumbing, not the optimiser
        assert manifest.background_splats is None
        write_splats(out / "background.ply", fitted)
        return ReconstructResult(fitted, {"iterations": 1, "depth_weight": 0.0}, out)

    monkeypatch.setattr(reconstruct_module, "reconstruct", fake_reconstruct)
    out = tmp_path / "out"
    report = run_scene(root / "manifest.json", out, progress=False)
    ran = {s["name"]: s["ran"] for s in report["stages"]}
    assert ran["reconstruct"] and ran["render"]
    assert (root / "manifest.json").read_text() == before
    assert load_manifest(root).background_splats is None
    rgb = read_image(out / "render/front/000000.png", channels=3)
    assert rgb.mean() > 0.2  # rendered from the fitted background, not an empty scene
    assert "reconstruction" in report["metrics"]  # evaluated on the fitted background
    assert json.loads((out / "report.json").read_text()) == report


def test_stage_metrics_merge_lists_and_replace_the_rest():
    into = {}
    for result in (StageResult({}, {"lateral": [{"method": "raw_3dgs"}]}),
                   StageResult({}, {"lateral": [{"method": "refined"}], "reconstruction": {"psnr": 1.0}})):
        merge_metrics(into, result.metrics)
    assert into == {"lateral": [{"method": "raw_3dgs"}, {"method": "refined"}], "reconstruction": {"psnr": 1.0}}
    merge_metrics(into, {"reconstruction": {"psnr": 2.0}})
    assert into["reconstruction"] == {"psnr": 2.0}
