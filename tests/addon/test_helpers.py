"""The add-on's bpy-free helpers: curve sampling, SUMO FCD reading, K -> Blender lens."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from blender_addon import camera_math, path_sampling
from symdrive_core import conventions
from symdrive_core.errors import InputError
from symdrive_core.traffic import fcd


def test_polyline_samples_by_arc_length_with_smooth_tangents():
    theta = np.linspace(0, np.pi, 181)
    path = path_sampling.Polyline(np.stack([5 * np.cos(theta), 5 * np.sin(theta), 0 * theta], 1))
    assert path.length == pytest.approx(5 * np.pi, rel=1e-4)
    pos, tan = path.sample([0.0, 5 * np.pi / 2, 100.0])
    np.testing.assert_allclose(pos[1], [0, 5, 0], atol=1e-3)
    np.testing.assert_allclose(tan[1], [-1, 0, 0], atol=1e-4)  # chords are a little shorter than the arc
    np.testing.assert_allclose(pos[2], [-5, 0, 0], atol=1e-9)  # clamped at the end of an open path
    yaw = path_sampling.heading(path.sample(np.linspace(0, path.length, 50))[1])
    assert np.all(np.diff(yaw) > 0) and yaw[-1] == pytest.approx(3 * np.pi / 2, abs=1e-4)


def test_cyclic_polyline_wraps_and_repeated_points_are_ignored():
    square = [(0, 0, 0), (1, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
    path = path_sampling.Polyline(square, cyclic=True)
    assert path.length == pytest.approx(4.0)
    pos, _ = path.sample([4.5, -0.5])
    np.testing.assert_allclose(pos, [[0.5, 0, 0], [0, 0.5, 0]], atol=1e-12)
    with pytest.raises(ValueError, match="two distinct points"):
        path_sampling.Polyline([(1, 1, 1), (1, 1, 1)])


def _fcd(tmp_path, body):
    p = tmp_path / "fcd.xml"
    p.write_text(f'<?xml version="1.0"?>\n<fcd-export>{body}</fcd-export>\n')
    return p


def test_fcd_angles_become_yaw_and_the_bumper_moves_to_the_centre(tmp_path):
    body = "".join(
        f'<timestep time="{t}"><vehicle id="a" x="{10 * t}" y="0" angle="90" speed="10"/>'
        f'<vehicle id="b" x="0" y="{5 * t}" z="1.5" angle="0" speed="5"/></timestep>'
        for t in (0, 1, 2)
    )
    tracks = fcd.read_fcd(_fcd(tmp_path, body))
    assert sorted(tracks) == ["a", "b"]
    np.testing.assert_allclose(tracks["a"].yaw, 0.0, atol=1e-12)
    np.testing.assert_allclose(tracks["b"].yaw, np.pi / 2)
    pos, _, inside = fcd.sample_track(tracks["a"], [-1.0, 0.5, 2.0, 3.0], length=4.0)
    np.testing.assert_array_equal(inside, [False, True, True, False])
    np.testing.assert_allclose(pos[1], [5.0 - 2.0, 0.0, 0.0], atol=1e-12)
    pos_b, _, _ = fcd.sample_track(tracks["b"], [1.0], length=4.0)
    np.testing.assert_allclose(pos_b[0], [0.0, 3.0, 1.5], atol=1e-12)
    assert fcd.yaw_to_sumo_angle(fcd.yaw_from_sumo_angle(271.0)) == pytest.approx(271.0)


def test_fcd_heading_across_north_does_not_spin():
    track = fcd.Track(
        "v", "car", np.array([0.0, 1.0]), np.zeros((2, 2)), np.zeros(2), np.array([350.0, 10.0]), np.zeros(2)
    )
    _, yaw, _ = fcd.sample_track(track, [0.5])
    assert np.degrees(yaw[0]) % 360 == pytest.approx(90.0)  # due north, not a 180-degree swing


@pytest.mark.parametrize(
    "body, field",
    [
        (
            '<timestep time="0"><vehicle id="a" y="0" angle="0"/></timestep>',
            "timestep[time=0.0].vehicle[id=a].x",
        ),
        ('<timestep time="0"><vehicle id="a" x="nan" y="0" angle="0"/></timestep>', "vehicle[id=a].x"),
        ('<timestep><vehicle id="a" x="0" y="0" angle="0"/></timestep>', "timestep.time"),
        ('<timestep time="0"><vehicle id="a" x="0" y="0" angle="0"/>', "not valid XML"),
    ],
)
def test_fcd_errors_name_the_field(tmp_path, body, field):
    with pytest.raises(InputError, match=field.replace("[", r"\[").replace("]", r"\]")):
        fcd.read_fcd(_fcd(tmp_path, body))


def test_fcd_named_by_a_folder_is_refused_naming_it(tmp_path):  # an import dialog with no file chosen
    with pytest.raises(InputError, match="cannot open|not a regular file"):
        fcd.read_fcd(tmp_path)


def test_fcd_rejects_other_xml(tmp_path):
    p = tmp_path / "net.xml"
    p.write_text("<net/>")
    with pytest.raises(InputError, match="expected <fcd-export>"):
        fcd.read_fcd(p)


@settings(max_examples=60, deadline=None)
@given(fx=st.floats(100, 2000), ratio=st.floats(0.5, 2.0), cx=st.floats(-50, 700), cy=st.floats(-50, 500))
def test_blender_lens_reproduces_k(fx, ratio, cx, cy):
    width, height = 640, 480
    K = conventions.intrinsics(fx, fx * ratio, cx, cy)
    lens = conventions.lens_from_intrinsics(K, width, height)
    assert min(lens.pixel_aspect_x, lens.pixel_aspect_y) == 1.0
    back = conventions.blender_intrinsics(
        width,
        height,
        lens.lens_mm,
        lens.sensor_width_mm,
        24.0,
        lens.sensor_fit,
        lens.shift_x,
        lens.shift_y,
        lens.pixel_aspect_x,
        lens.pixel_aspect_y,
    )
    np.testing.assert_allclose(back, K, rtol=1e-9, atol=1e-9)


def test_skew_and_bad_offsets_are_refused():
    with pytest.raises(ValueError, match="skew"):
        conventions.lens_from_intrinsics([[500, 3, 320], [0, 500, 240], [0, 0, 1]], 640, 480)
    assert camera_math.parse_offsets(" -1.5, 1.5 ;3") == [-1.5, 1.5, 3.0]
    with pytest.raises(ValueError, match="'left'"):
        camera_math.parse_offsets("1, left")
