"""Road polylines, FCD reading and box overlap: pure numpy, no SUMO."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from symdrive_core.errors import InputError
from symdrive_core.rotations import quat_from_yaw
from symdrive_core.scene import Actor, Pose
from symdrive_core.scene.road import (
    Road,
    arc_points,
    offset_polyline,
    project_onto,
    road_from_json,
    road_from_spec,
)
from symdrive_core.traffic.fcd import read_fcd
from symdrive_core.traffic.overlap import (
    OverlapError,
    check_actors,
    footprints,
    frame_gaps,
    require_no_overlap,
)


def test_offset_polyline_stays_parallel_through_a_bend():
    line = arc_points(120.0, 60.0)[:, :2]
    for offset in (-5.25, -1.75, 1.75):
        shifted = offset_polyline(line, offset)
        midpoints = 0.5 * (shifted[1:] + shifted[:-1])  # each shifted segment parallel to its original
        lateral, _, _ = project_onto(line, midpoints)
        np.testing.assert_allclose(lateral, offset, atol=1e-6)


def test_arc_has_requested_length_and_radius():
    pts = arc_points(100.0, -50.0)
    road = Road(pts, 1)
    assert road.length == pytest.approx(100.0, rel=1e-3)
    np.testing.assert_allclose(np.linalg.norm(pts[:, :2] - [0.0, -50.0], axis=1), 50.0, atol=1e-9)


def test_ground_height_interpolates_the_centre_line():
    road = Road(np.array([[0.0, 0.0, 1.0], [10.0, 0.0, 3.0], [20.0, 0.0, 3.0]]), 2)
    np.testing.assert_allclose(road.ground_height(np.array([[5.0, 1.75], [15.0, -1.75]])), [2.0, 3.0])


def test_lane_offsets_keep_right_with_oncoming_lanes():
    road = Road(np.array([[0.0, 0, 0], [1.0, 0, 0]]), lanes=4, lane_width=3.0, oncoming=2)
    assert road.lane_offset(True) == pytest.approx(-3.0) and road.lane_offset(False) == pytest.approx(3.0)
    one_way = Road(np.array([[0.0, 0, 0], [1.0, 0, 0]]), lanes=3, lane_width=3.0)
    assert one_way.lane_offset(True) == pytest.approx(0.0)


@pytest.mark.parametrize("road,field", [
    ({"centerline": [[0, 0, 0]], "lanes": 2}, "centerline"),
    ({"centerline": [[0, 0, 0], [0, 0, 1]], "lanes": 2}, "centerline"),
    ({"centerline": [[0, 0, 0], [5, 0, 0]], "lanes": 0}, "lanes"),
    ({"centerline": [[0, 0, 0], [5, 0, 0]], "lanes": 2, "lane_width": -1}, "lane_width"),
    ({"centerline": [[0, 0, 0], [5, 0, 0]], "lanes": 2, "oncoming": 2}, "oncoming"),
])
def test_bad_road_names_the_field(road, field):
    with pytest.raises(InputError, match=rf"ground_truth\.road\.{field}"):
        road_from_json(road, "pkg/manifest.json")


@pytest.mark.parametrize("spec", ["straight", "straight:-5", "curved:100", "curved:100:0", "bendy:3"])
def test_bad_road_spec_is_refused(spec):
    with pytest.raises(InputError, match="straight:LENGTH or curved"):
        road_from_spec(spec)


def test_fcd_front_bumper_and_angle_become_box_centre_and_yaw(tmp_path):
    fcd = tmp_path / "fcd.xml"
    fcd.write_text("""<fcd-export>
 <timestep time="0.00"><vehicle id="a" x="110.0" y="220.0" angle="0.00" type="car" speed="1.0"/>
  <vehicle id="b" x="115.0" y="205.0" angle="90.00" type="van" speed="2.0"/></timestep>
 <timestep time="0.10"><vehicle id="a" x="110.0" y="220.1" angle="0.00" type="car" speed="1.0"/></timestep>
</fcd-export>""")
    tracks = read_fcd(fcd)
    a, b = tracks["a"], tracks["b"]
    np.testing.assert_allclose(a.times, [0.0, 0.1])
    # north: centre 2 m south of the front
    np.testing.assert_allclose(a.centre(4.0, (100.0, 200.0)), [[10.0, 18.0], [10.0, 18.1]])
    np.testing.assert_allclose(a.yaw, np.pi / 2)
    np.testing.assert_allclose(b.centre(6.0, (100.0, 200.0)), [[12.0, 5.0]])  # east: 3 m west of the front
    np.testing.assert_allclose(b.yaw, 0.0, atol=1e-12)
    assert b.vtype == "van" and b.speed[0] == 2.0


def _rect(x, y, yaw, w=2.0, l=4.0):
    return footprints(np.array([[x, y]]), np.array([yaw]), np.array([[w, l, 1.5]]))[0]


@pytest.mark.parametrize("b,gap", [
    ((7.0, 0.0, 0.0), 3.0),  # same lane, bumper to bumper
    ((0.0, 3.5, 0.0), 1.5),  # side by side
    ((5.0, 0.0, np.pi / 2), 2.0),  # crossing: B spans x in [4, 6]
    ((4.0, 0.0, 0.0), 0.0),  # touching counts as no overlap
    ((3.0, 1.0, 0.3), -1.0),  # overlapping
])
def test_gap_between_two_boxes(b, gap):
    _, _, gaps = frame_gaps(np.stack([_rect(0.0, 0.0, 0.0), _rect(*b)]))
    assert gaps[0] == pytest.approx(gap, abs=1e-9)


@settings(max_examples=60, deadline=None)
@given(st.floats(-8, 8), st.floats(-8, 8), st.floats(-np.pi, np.pi), st.floats(-np.pi, np.pi))
def test_gap_is_rigid_invariant_and_overlap_matches_sampling(x, y, yaw_b, turn):
    a, b = _rect(0.0, 0.0, 0.0), _rect(x, y, yaw_b)
    _, _, g = frame_gaps(np.stack([a, b]))
    R = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    _, _, g_turned = frame_gaps(np.stack([a @ R.T + 5.0, b @ R.T + 5.0]))
    assert g_turned[0] == pytest.approx(g[0], abs=1e-6)
    # a grid of points inside B: any of them inside A means overlap
    u, v = np.meshgrid(np.linspace(-0.49, 0.49, 15), np.linspace(-0.49, 0.49, 15))
    pts = np.array([x, y]) + np.outer(u.ravel(), 4.0 * np.array([np.cos(yaw_b), np.sin(yaw_b)])) \
        + np.outer(v.ravel(), 2.0 * np.array([-np.sin(yaw_b), np.cos(yaw_b)]))
    inside_a = (np.abs(pts[:, 0]) < 2.0) & (np.abs(pts[:, 1]) < 1.0)
    if inside_a.any():
        assert g[0] < 0


def _actor(name, xs, iid):
    return Actor(name, "inserted", "a.ply", None, [None if x is None else Pose(np.array([x, 0.0, 0.75]), quat_from_yaw(0.0))
                                                   for x in xs], np.array([2.0, 4.0, 1.5]), iid)


def test_check_actors_reports_minimum_gap_and_overlaps():
    actors = [_actor("a", [0.0, 0.0, 0.0], 1), _actor("b", [10.0, 6.0, 3.0], 2), _actor("c", [None, 30.0, None], 3)]
    report = check_actors(actors, 3)
    assert report.min_gap == pytest.approx(2.0) and report.frame == 1 and report.pair == ("a", "b")
    assert report.overlaps == [(2, "a", "b")]
    with pytest.raises(OverlapError, match="frame 2: a and b"):
        require_no_overlap(report)
