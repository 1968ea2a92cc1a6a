"""Public API details: lazy package import, SH, thread settings, argument checks."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import torch

from symdrive_core.gaussians import SH_C0
from symdrive_core.splat import eval_sh, rasterize
from symdrive_core.splat.oracle import _sh_color
from symdrive_core.splat.sh import sh_to_color

from .scenes import args_of, random_scene


def test_package_import_is_light():
    code = "import sys, symdrive_core.splat; print('torch' in sys.modules, 'numba' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["False", "False"]


def test_exported_names_are_the_functions_even_after_their_modules_load():
    import symdrive_core.splat.rasterizer  # noqa: F401  (binds the submodule on the package)
    import symdrive_core.splat.render  # noqa: F401
    from symdrive_core import splat
    from symdrive_core.splat.rasterizer import RasterizePixels

    assert callable(splat.rasterize) and not isinstance(splat.rasterize, type(sys))
    assert RasterizePixels is splat.RasterizePixels
    assert set(splat.__all__) <= set(dir(splat))
    for name in splat.__all__:
        assert not isinstance(getattr(splat, name), type(sys)), name


@pytest.mark.parametrize("deg", [0, 1, 2, 3])
def test_sh_matches_independent_formula(deg):
    g = torch.Generator().manual_seed(deg)
    sh = torch.randn(50, (deg + 1) ** 2, 3, generator=g, dtype=torch.float64)
    dirs = torch.randn(50, 3, generator=g, dtype=torch.float64) * 3
    ours = sh_to_color(deg, sh, dirs).numpy()
    np.testing.assert_allclose(ours, _sh_color(deg, sh.numpy(), dirs.numpy()), atol=1e-13)
    assert abs(float(eval_sh(0, sh[:1, :1], dirs[:1])[0, 0]) - SH_C0 * float(sh[0, 0, 0])) < 1e-15


def test_sh_zero_direction_has_finite_gradient():
    sh = torch.randn(3, 16, 3, dtype=torch.float64, requires_grad=True)
    dirs = torch.zeros(3, 3, dtype=torch.float64, requires_grad=True)
    eval_sh(3, sh, dirs).sum().backward()
    assert torch.isfinite(sh.grad).all() and torch.isfinite(dirs.grad).all()


def test_torch_thread_setting_survives_rendering():
    before = torch.get_num_threads()
    try:
        torch.set_num_threads(1)
        s = random_scene(50, 0, 1, dtype=torch.float32)
        params = [s[k].requires_grad_(True) for k in ("means", "quats", "scales", "opacities", "colors")]
        rgb, alpha, info = rasterize(*params, s["viewmat"], s["K"], s["width"], s["height"])
        rgb.sum().backward()
        assert torch.get_num_threads() == 1
    finally:
        torch.set_num_threads(before)


def test_sh_degree_subset_and_errors():
    s = random_scene(40, 3, 2)
    a = rasterize(*args_of(s), sh_degree=1)[0]
    s1 = dict(s, colors=s["colors"][:, :4])
    b = rasterize(*args_of(s1))[0]
    torch.testing.assert_close(a, b, atol=0, rtol=0)
    with pytest.raises(ValueError):
        rasterize(*args_of(dict(s, colors=s["colors"][:, :4])), sh_degree=2)
    with pytest.raises(ValueError):
        rasterize(*args_of(s), backend="opengl")
    with pytest.raises(ValueError):
        rasterize(*args_of(s), extent="5sigma")


def test_info_contents():
    s = random_scene(60, 0, 3, dtype=torch.float32)
    means2d_leaf = s["means"].requires_grad_(True)
    rgb, alpha, info = rasterize(*args_of(s), render_depth=True)
    assert info["radii"].shape == (60, 2) and info["radii"].dtype == torch.int32
    assert info["depth"].shape == (50, 70, 1) and info["backend"] == "numba"
    info["means2d"].retain_grad()
    rgb.sum().backward()
    assert info["means2d"].grad.shape == (60, 2) and float(info["means2d"].grad.abs().sum()) > 0
    assert means2d_leaf.grad is not None


def test_frame_without_gradients_bins_without_list_positions():
    """A no-grad frame skips the per-Gaussian list positions (only the backward reads them) and
    renders the same image; a frame with gradients keeps them (and cuts the lists to the tiles each
    ellipse reaches: fewer or as many pairs)."""
    s = random_scene(80, 1, 4, dtype=torch.float32)
    with torch.no_grad():
        rgb0, alpha0, info0 = rasterize(*args_of(s))
    leaf = [t.detach().requires_grad_(True) for t in args_of(s)[:5]]
    rgb1, alpha1, info1 = rasterize(*leaf, *args_of(s)[5:])
    assert info0["bins"].rows.shape[0] == 0 and info0["bins"].row_start.shape[0] == 0
    assert info1["bins"].rows.shape[0] == info1["n_isect"] > 0
    assert info1["n_isect"] <= info0["n_isect"]
    np.testing.assert_array_equal(rgb0.numpy(), rgb1.detach().numpy())
    np.testing.assert_array_equal(alpha0.numpy(), alpha1.detach().numpy())
    (rgb1.sum() + alpha1.sum()).backward()
    assert all(t.grad is not None for t in leaf)
