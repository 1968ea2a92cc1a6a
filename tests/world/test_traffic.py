"""Moving traffic of the built-in street (``scripts/world/traffic.py``): the motion plan is
deterministic, stays on its lanes, clear of the ego and of each other, and in view; a tiny Cycles
package's existing actors, vehicle masks and edit truth agree with what Blender rendered; and
the ground-truth readers return the ``vehicles`` and ``edits`` blocks."""

import sys

import numpy as np
import pytest

from symdrive_core import conventions
from symdrive_core.io.images import read_image, read_mask
from symdrive_core.rotations import quat_from_yaw
from symdrive_core.scene import check_files, load_manifest, parse_manifest
from symdrive_core.scene.ground_truth import edit_truth, vehicle_masks
from symdrive_core.scene.manifest import ManifestError
from symdrive_core.scene.poses import yaw_of
from tests.conftest import manifest_dict
from tests.scripts import SCRIPTS, write_world

DURATION = 3.9  # 40 frames 1 m apart at the ego's 10 m/s
TIMES = np.linspace(0.0, DURATION, 40)
SEEDS = range(6)


@pytest.fixture(scope="module")
def world():
    """The generator's modules (they need Blender's Python, the ``bpy`` wheel)."""
    pytest.importorskip("bpy")
    if str(SCRIPTS) not in sys.path:
        sys.path.insert(0, str(SCRIPTS))
    from world import drive, street, traffic

    return drive, street, traffic


@pytest.fixture(scope="module")
def plans(world):
    _, street, traffic = world
    ego = traffic.ego_vehicle(10.0)
    return {seed: (street.Street(amp=1.0 + 0.25 * seed, period=140.0 + 10 * seed), ego,
                   traffic.plan(5, seed, DURATION, ego)) for seed in SEEDS}


# ---------------------------------------------------------------- the plan (numpy only, no render)

@pytest.mark.blender
def test_the_plan_is_deterministic_per_seed(world, plans):
    traffic = world[2]
    _, ego, vehicles = plans[3]
    assert traffic.plan(5, 3, DURATION, ego) == vehicles
    assert traffic.plan(5, 4, DURATION, ego) != vehicles


@pytest.mark.blender
def test_both_directions_and_several_body_shapes(plans):
    for _, _, vehicles in plans.values():
        assert [v.role for v in vehicles] == ["lead", "oncoming", "overtaker", "oncoming", "lead"]
        assert {v.direction for v in vehicles} == {1, -1}
        assert all((v.direction < 0) == (v.role == "oncoming") for v in vehicles)
        assert len({v.kind for v in vehicles}) > 1


@pytest.mark.blender
def test_vehicles_stay_on_their_lanes_and_clear_of_each_other(world, plans):
    _, street_mod, traffic = world
    half = street_mod.LANE_WIDTH / 2
    for street, ego, vehicles in plans.values():
        for v in vehicles:
            lateral = v.lateral(TIMES)
            assert np.all(np.abs(lateral) <= half + 1e-9)
            for t in TIMES[::7]:
                (x, y), _ = v.ground(street, t)
                assert abs(y - street.centre_y(x)) <= half + 0.05  # within the two lanes
        for i, a in enumerate([ego, *vehicles]):
            for b in vehicles[i:]:
                assert not traffic.conflict(a.at(TIMES), b.at(TIMES)).any()


@pytest.mark.blender
def test_speeds_are_in_range_and_yaw_follows_the_motion(plans):
    wlh = [1.8, 4.6, 1.5]
    for street, _, vehicles in plans.values():
        for v in vehicles:
            poses = [v.pose(street, t, wlh) for t in TIMES]
            xyz = np.array([p.translation for p in poses])
            assert np.allclose(xyz[:, 2], 0.75)  # the box centre half the height above the road
            step = np.diff(xyz[:, :2], axis=0)
            speed = np.linalg.norm(step, axis=1) / np.diff(TIMES)
            assert np.all((speed > 7.0) & (speed < 15.5)), (v.role, speed.min(), speed.max())
            ahead, behind = ([v.pose(street, t + d, wlh).translation for t in TIMES] for d in (0.01, -0.01))
            chord = np.array(ahead) - np.array(behind)
            motion = np.arctan2(chord[:, 1], chord[:, 0])
            yaw = np.array([yaw_of(p.rotation) for p in poses])
            assert np.allclose(np.angle(np.exp(1j * (motion - yaw))), 0, atol=2e-3)
            assert np.cos(yaw[0]) * v.direction > 0.99  # along the road, in its own direction


@pytest.mark.blender
def test_the_lane_changer_moves_into_the_egos_lane(world, plans):
    _, _, traffic = world
    for street, _, vehicles in plans.values():
        (v,) = [v for v in vehicles if v.lateral0 != v.lateral1]
        assert v.lateral(0.0) > 0 and v.lateral(DURATION) == traffic.EGO_LANE
        during = v.change_start + v.change_seconds / 2
        assert yaw_of(v.pose(street, during, [1.8, 4.6, 1.5]).rotation) < float(street.heading(v.x(during))) - 0.05


@pytest.mark.blender
def test_every_vehicle_is_in_view_in_a_good_share_of_the_frames(world, plans):
    drive = world[0]
    K = conventions.intrinsics_from_fov(256, 144, 2 * np.arctan(18 / 24))  # the world's 24 mm lens
    for street, _, vehicles in plans.values():
        w2c = [conventions.invert_rigid(drive.camera_pose(street, 10.0 * t)) for t in TIMES]
        for v in vehicles:
            seen = 0
            for t, view in zip(TIMES, w2c):
                uv, z = conventions.project_points(v.pose(street, t, [1.8, 4.6, 1.5]).translation[None], view, K)
                seen += bool(z[0] > 0 and 0 <= uv[0, 0] < 256 and 0 <= uv[0, 1] < 144)
            assert seen >= 0.25 * len(TIMES), (v.role, seen)


@pytest.mark.blender
def test_edited_poses_follow_the_trajectory_or_cross_the_road(world):
    """Retimed: the car's own pose RETIME_S later; moved: one lane width across, same yaw."""
    _, street_mod, traffic = world
    street = street_mod.Street(amp=2.0, period=160.0)
    cars = traffic.Traffic(street, 5, 3, list(TIMES), traffic.ego_vehicle(10.0))
    retimed = moved = 0
    for k, v in enumerate(cars.vehicles):
        for f in range(0, len(TIMES), 6):
            later = cars.retimed(k, f)
            if later is not None:
                expected = v.pose(street, TIMES[f] + traffic.RETIME_S, cars.wlh(k))
                assert np.allclose(later.matrix(), expected.matrix())
                retimed += 1
            across = cars.moved(k, f)
            if across is not None:
                pose, lateral_m = across
                recorded = cars.poses[k][f]
                assert abs(lateral_m) == street_mod.LANE_WIDTH and np.sign(lateral_m) == -np.sign(v.lateral(TIMES[f]))
                assert np.linalg.norm(pose.translation - recorded.translation) == pytest.approx(street_mod.LANE_WIDTH)
                assert np.array_equal(pose.rotation, recorded.rotation)
                moved += 1
    assert retimed > 10 and moved > 10


# ---------------------------------------------------------------- a tiny Cycles package

@pytest.fixture(scope="module")
def package(world, tmp_path_factory):
    """64x36, 4 frames (frame 1 held out), one traffic car, rendered in this process so that the
    Blender objects can be compared with what the manifest says."""
    root = tmp_path_factory.mktemp("traffic")
    writer = write_world(root, [
        "--width", "64", "--height", "36", "--frames", "4", "--samples", "4", "--offsets",
        "--holdout-every", "3", "--placements", "0", "--points", "2000", "--asset-splats", "300",
        "--traffic", "1", "--edit-pixels", "10"])
    return writer, load_manifest(root)


@pytest.mark.blender
def test_the_traffic_car_is_an_existing_actor_at_the_pose_blender_rendered(package):
    writer, m = package
    check_files(m)
    assert m.ground_truth["generator"]["traffic"] == 1
    (actor,) = m.actors
    obj = writer.traffic.objects[0]
    assert (actor.id, actor.kind, actor.splats, actor.mesh, actor.instance_id) == ("car_0", "existing", None, None, 1)
    assert np.allclose(actor.wlh, list(obj["wlh"]))
    verts = np.array([v.co for v in obj.data.vertices])
    assert np.allclose(verts.min(0) + verts.max(0), 0, atol=1e-6)  # mesh centred on its box
    for f, pose in enumerate(actor.poses):
        writer.traffic.show(f)
        world_matrix = np.array(obj.matrix_world)
        assert pose is not None and np.allclose(world_matrix, pose.matrix(), atol=1e-6)
        world_verts = verts @ world_matrix[:3, :3].T + world_matrix[:3, 3]
        assert world_verts[:, 2].min() == pytest.approx(0.0, abs=1e-5)  # wheels on the road


@pytest.mark.blender
def test_vehicle_masks_cover_the_car_where_it_is_in_view(package):
    _, m = package
    masks = vehicle_masks(m)
    assert sorted(masks) == [0, 1, 2, 3]
    cam = m.cameras[0]
    for f, rel in masks.items():
        mask = read_mask(m.resolve(rel)) > 0.5
        cf = cam.frames[f]
        uv, z = conventions.project_points(m.actors[0].poses[f].translation[None], cf.world_to_camera, cf.K)
        assert z[0] > 0 and 0 <= uv[0, 0] < cam.width and 0 <= uv[0, 1] < cam.height
        assert mask.any() and mask[int(uv[0, 1]), int(uv[0, 0])]


@pytest.mark.blender
def test_edit_truth_is_written_and_read_back(package):
    writer, m = package
    edits = edit_truth(m)
    assert [(e.kind, e.actor, e.frame) for e in edits] == [("remove", "car_0", 1), ("move", "car_0", 1),
                                                            ("retime", "car_0", 1)]
    recorded = m.actors[0].poses[1]
    remove, move, retime = edits
    assert remove.pose is None and remove.lateral_m is None and remove.shift_s is None
    assert np.array_equal(read_mask(m.resolve(remove.mask)), read_mask(m.resolve(vehicle_masks(m)[1])))
    without = read_image(m.resolve(remove.image), channels=3)
    with_car = read_image(m.resolve(m.cameras[0].frames[1].image), channels=3)
    car = read_mask(m.resolve(remove.mask)) > 0.5
    assert np.abs(without - with_car)[car].mean() > 0.05
    assert move.lateral_m == pytest.approx(3.5)  # from the ego's lane to the other one
    assert np.linalg.norm(move.pose.translation - recorded.translation) == pytest.approx(3.5, abs=1e-6)
    assert np.allclose(move.pose.rotation, recorded.rotation)
    later = writer.traffic.vehicles[0].pose(writer.street, m.frames[1].timestamp + 0.5, m.actors[0].wlh)
    assert retime.shift_s == 0.5 and np.allclose(retime.pose.matrix(), later.matrix())
    for e in edits:
        mask = read_mask(m.resolve(e.mask)) > 0.5
        assert read_image(m.resolve(e.image)).shape[:2] == (36, 64) and mask.sum() == e.mask_pixels > 0


# ---------------------------------------------------------------- the readers on a hand-written manifest

def _with_truth(tmp_path, gt):
    d = manifest_dict(n_frames=4)
    d["ground_truth"] = gt
    return parse_manifest(d, tmp_path / "manifest.json")


EDITS = [
    {"kind": "remove", "actor": "car_0", "camera": "front", "frame": 2, "image": "gt/edits/00/image.png",
     "mask": "gt/edits/00/mask.png", "pose": None, "mask_pixels": 40},
    {"kind": "move", "actor": "car_0", "frame": 2, "image": "gt/edits/01/image.png", "mask": "gt/edits/01/mask.png",
     "pose": {"translation": [10.0, 2.5, 0.75], "rotation": quat_from_yaw(0.1).tolist()}, "lateral_m": 3.5},
    {"kind": "retime", "actor": "car_0", "frame": 3, "image": "gt/edits/02/image.png",
     "mask": "gt/edits/02/mask.png", "pose": {"translation": [15.0, -1.0, 0.75], "rotation": [1, 0, 0, 0]},
     "shift_s": 0.5},
]


def test_the_readers_return_the_vehicle_masks_and_edits(tmp_path):
    m = _with_truth(tmp_path, {"camera": "front", "edits": EDITS,
                               "vehicles": {"camera": "front", "frames": {"3": "v3.png", "0": "v0.png"}}})
    assert vehicle_masks(m) == {0: "v0.png", 3: "v3.png"}
    remove, move, retime = edit_truth(m)
    assert (remove.kind, remove.frame, remove.pose, remove.mask_pixels) == ("remove", 2, None, 40)
    assert move.camera == "front" and move.lateral_m == 3.5 and move.shift_s is None
    assert np.allclose(move.pose.translation, [10.0, 2.5, 0.75]) and yaw_of(move.pose.rotation) == pytest.approx(0.1)
    assert (retime.frame, retime.shift_s, retime.image) == (3, 0.5, "gt/edits/02/image.png")
    empty = _with_truth(tmp_path, {"camera": "front"})
    assert vehicle_masks(empty) == {} and edit_truth(empty) == []


@pytest.mark.parametrize("gt, field", [
    ({"edits": [{**EDITS[0], "frame": 4}]}, "ground_truth.edits[0].frame"),
    ({"edits": [{**EDITS[0], "camera": "back"}]}, "ground_truth.edits[0].camera"),
    ({"edits": [{**EDITS[0], "kind": "swap"}]}, "ground_truth.edits[0].kind"),
    ({"edits": [{**EDITS[1], "lateral": 3.5}]}, "ground_truth.edits[0].lateral"),
    ({"vehicles": {"frames": {"9": "v.png"}}}, "ground_truth.vehicles.frames.9"),
    ({"vehicles": {"frames": {"0": "v.png"}, "camera": "back"}}, "ground_truth.vehicles.camera"),
], ids=lambda v: v if isinstance(v, str) else "")
def test_a_wrong_edit_or_vehicle_entry_names_its_field(tmp_path, gt, field):
    with pytest.raises(ManifestError) as exc:
        _with_truth(tmp_path, gt)
    assert exc.value.field == field, str(exc.value)



# ---------------------------------------------------------------- parked cars as existing actors

@pytest.mark.blender
def test_parked_cars_are_existing_actors_with_removal_truth(world, tmp_path):
    """--parked-existing without traffic: the parked actors sit where Blender put the cars and a
    held-out frame has a parked car removed (recorded mask, Cycles render without it)."""
    writer = write_world(tmp_path, [
        "--width", "64", "--height", "36", "--frames", "4", "--samples", "4", "--offsets",
        "--holdout-every", "3", "--placements", "0", "--points", "2000", "--asset-splats", "300",
        "--edit-pixels", "5", "--parked-existing"])
    m = load_manifest(tmp_path)
    check_files(m)
    assert m.actors and all(a.kind == "existing" and a.id.startswith("parked_") for a in m.actors)
    assert [a.instance_id for a in m.actors] == list(range(1, len(m.actors) + 1))
    assert "vehicles" not in m.ground_truth
    for actor, obj in zip(m.actors, writer.parked.objects):
        assert np.allclose(actor.wlh, list(obj["wlh"]))
        for pose in actor.poses:
            assert np.allclose(pose.matrix(), np.array(obj.matrix_world), atol=1e-5)
    removals = [e for e in edit_truth(m) if e.kind == "remove" and e.actor.startswith("parked_")]
    assert removals
    for e in removals:
        assert m.resolve(e.image).is_file() and m.resolve(e.mask).is_file() and e.pose is None
        car = read_mask(m.resolve(e.mask)) > 0.5
        assert car.sum() == e.mask_pixels >= 5
        without = read_image(m.resolve(e.image), channels=3)
        recorded = read_image(m.resolve(m.cameras[0].frames[e.frame].image), channels=3)
        assert np.abs(without - recorded)[car].mean() > 0.02
