"""A family of streets: the generator's camera, ground materials and sensor vary from the built-in
street's and reach the package (``scripts/make_world.py --camera-height --pitch --lens-mm
--material-jitter --noise --blur --exposure-jitter``), and the sensor model itself."""

import sys

import numpy as np
import pytest

from symdrive_core.io.images import read_image
from symdrive_core.scene import check_files, load_manifest
from tests.scripts import SCRIPTS, write_world

if str(SCRIPTS) not in sys.path:
    sys.path.insert(0, str(SCRIPTS))
from world.sensor import SensorEffects, gaussian_blur  # noqa: E402  (scripts/world, bpy-free)

VARIED = ["--camera-height", "1.9", "--pitch", "6", "--lens-mm", "35", "--material-jitter", "0.4",
          "--noise", "0.02", "--blur", "0.7", "--exposure-jitter", "0.2"]


def test_the_sensor_model_is_seeded_per_frame_and_image():
    rng = np.random.default_rng(0)
    clean = rng.uniform(0.2, 0.7, (30, 40, 3)).astype(np.float32)
    exposure = SensorEffects(exposure_jitter=0.3)
    a, b = exposure.apply(clean, 0, 3, "gt/train/000003.png"), exposure.apply(clean, 0, 3, "gt/lateral/x.png")
    gain = a / clean
    assert np.allclose(gain, gain.flat[0], rtol=1e-5) and 0.74 < gain.flat[0] < 1.35 and gain.flat[0] != 1.0
    assert np.array_equal(a, b)  # one frame, one exposure
    assert not np.array_equal(a, exposure.apply(clean, 0, 4, "gt/train/000004.png"))
    noise = SensorEffects(noise=0.02)
    n1, n2 = noise.apply(clean, 0, 3, "gt/train/000003.png"), noise.apply(clean, 0, 3, "gt/lateral/x.png")
    assert abs(float((n1 - clean).std()) - 0.02) < 0.002 and not np.array_equal(n1, n2)  # own draw per image
    assert np.array_equal(n1, noise.apply(clean, 0, 3, "gt/train/000003.png"))  # and repeatable
    assert SensorEffects().apply(clean, 0, 3, "k") is clean  # off: the render as it is



def test_the_generator_refuses_an_out_folder_of_other_files(tmp_path, capsys):
    """``--out`` is replaced whole: a folder of the user's files (no package) was deleted."""
    pytest.importorskip("bpy")
    from tests.scripts import load_script

    (tmp_path / "notes.txt").write_text("mine")
    assert load_script("make_world").main(["--out", str(tmp_path), "--frames", "2"]) == 2
    assert "is no new or empty folder and no scene package" in capsys.readouterr().err
    assert (tmp_path / "notes.txt").read_text() == "mine"

def test_the_blur_has_the_asked_width_and_keeps_the_mean():
    dot = np.zeros((41, 41, 3), np.float32)
    dot[20, 20] = 1.0
    for sigma in (0.7, 1.5):
        out = gaussian_blur(dot, sigma)[:, :, 0]
        x = np.arange(41) - 20
        col = out.sum(0)
        assert abs(out.sum() - 1.0) < 1e-5 and np.argmax(col) == 20
        assert abs(np.sqrt((col * x * x).sum()) - sigma) < 0.02 * sigma + 0.01


@pytest.fixture(scope="module")
def varied(tmp_path_factory):
    """A 48x27, two-frame street with every variation, rendered in this process."""
    pytest.importorskip("bpy")
    root = tmp_path_factory.mktemp("family")
    writer = write_world(root, [
        "--width", "48", "--height", "27", "--frames", "2", "--samples", "2", "--offsets", "1.0",
        "--lateral-every", "2", "--holdout-every", "0", "--placements", "0", "--points", "500",
        "--asset-splats", "200", *VARIED])
    return writer, load_manifest(root)


@pytest.mark.blender
def test_the_variations_reach_the_package(varied):
    import bpy

    writer, m = varied
    check_files(m)
    gen = m.ground_truth["generator"]
    assert (gen["camera_height_m"], gen["pitch_deg"], gen["lens_mm"], gen["material_jitter"]) == (1.9, 6.0, 35.0, 0.4)
    assert gen["sensor"] == {"noise": 0.02, "blur_px": 0.7, "exposure_jitter": 0.2}
    cam = m.cameras[0]
    for cf in cam.frames:  # the camera's height, pitch and focal length
        assert cf.camera_to_world[2, 3] == pytest.approx(1.9)
        assert -cf.camera_to_world[2, 2] == pytest.approx(np.sin(np.radians(6.0)))
        assert cf.K[0, 0] == pytest.approx(35.0 / 36.0 * 48)
    asphalt = bpy.data.materials["asphalt"]["albedo"]  # the built-in asphalt's mean albedo, tinted
    assert not np.allclose(asphalt, [0.09, 0.09, 0.0925], atol=1e-3)
    assert np.all(np.abs(np.asarray(asphalt) / [0.09, 0.09, 0.0925] - 1) <= 0.4 + 1e-6)
    clean = writer._render(cam.frames[0].camera_to_world, 0)["rgb"]  # Cycles is seeded: the same render
    recorded = read_image(m.resolve(cam.frames[0].image))
    expected = writer.sensor.apply(clean, 0, 0, cam.frames[0].image)
    assert np.abs(recorded - expected).max() <= 0.5 / 255 + 1e-6  # every recorded image went through it
    assert np.abs(recorded - clean).mean() > 0.01
