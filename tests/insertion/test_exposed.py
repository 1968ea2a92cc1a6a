"""What an edit of a recorded vehicle exposes: the region, the segment-box test that decides
whether a frame saw a surface past the recorded vehicles (against dense sampling in float64), and
the unseen part on a scene whose truth is known."""

import numpy as np
import pytest

from symdrive_core.eval.views import TrafficRenderer
from symdrive_core.insertion.exposed import _segment_hits_box, exposed_region, inpaint_region
from symdrive_core.rotations import quat_from_yaw
from symdrive_core.scene import Pose, load_manifest
from symdrive_core.scene.camera import CameraView


def test_segment_box_test_matches_dense_sampling():
    rng = np.random.default_rng(0)
    pose = Pose(np.array([1.0, -2.0, 0.5]), quat_from_yaw(0.7))
    half = np.array([2.0, 0.9, 0.7])
    start = np.array([-4.0, 1.0, 1.5])
    ends = pose.translation + rng.uniform(-4, 4, (400, 3))
    hits = _segment_hits_box(start, ends, pose, half)
    s = np.linspace(0.0, 0.999, 4000)[None, :, None]
    samples = start + s * (ends - start)[:, None, :]
    local = (samples - pose.translation) @ pose.R
    inside = (np.abs(local) <= half).all(-1).any(1)
    assert 20 < hits.sum() < 380 and np.array_equal(hits, inside)


def test_the_exposed_region_is_where_the_car_was_and_nothing_is_now():
    was = np.zeros((10, 12))
    was[2:6, 2:8] = 1.0
    now = np.zeros((10, 12))
    now[3:8, 6:10] = 1.0
    region = exposed_region({"car": was}, {"other": now}, ["car"], dilate_px=0)
    assert region.sum() == 4 * 6 - 3 * 2 and not region[3:6, 6:8].any()
    assert exposed_region({"car": was}, {"car": was}, ["car"], dilate_px=0) is None  # not moved: nothing exposed
    assert exposed_region({}, {}, ["car"]) is None  # not in view where it was recorded


@pytest.fixture(scope="module")
def removed_box(moving_box):
    root, result, *_ = moving_box
    m = load_manifest(root)
    car = m.actor("car_1")
    car.recorded_poses, car.poses = list(car.poses), [None] * len(car.poses)
    return m, TrafficRenderer(result.gaussians, result.actors)


@pytest.mark.parametrize(("frame", "unseen"), [(0, True), (6, False)])
def test_only_what_no_frame_saw_is_inpainted(removed_box, frame, unseen):
    """Removed at the first frame the box uncovers wall the later frames saw only behind it; in the
    middle of the drive the frames around saw everything it covered."""
    m, renderer = removed_box
    _, recorded = renderer.render(m, "front", frame, recorded=True)
    _, now = renderer.render(m, "front", frame)
    exposed = exposed_region(recorded, now, ["car_1"])
    region = inpaint_region(m, CameraView.of_frame(m.cameras[0], frame), recorded, now, ["car_1"],
                            renderer.street_depth(m, "front", frame))
    assert exposed.sum() > 300
    if unseen:
        assert 50 < region.sum() < exposed.sum() and not (region & ~exposed).any()
    else:
        assert region is None
