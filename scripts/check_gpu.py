"""Check the GPU path: gsplat on CUDA against the float64 oracle, gradients included, and its speed
next to the CPU kernels, measured in one run.

    python scripts/check_gpu.py                 # needs CUDA and gsplat (pip install -e ".[gpu]")
    python scripts/check_gpu.py --json out.json
    python scripts/check_gpu.py --backend numba --quick   # the same checks on the CPU kernels

Agreement: random scenes (SH degree 0 and 3, hard cases: Gaussians behind and across the near
plane, huge and needle-thin ones, opacities near the clamp and the threshold) rendered by the
backend under test in float32 and by ``splat.oracle`` in float64; the largest RGB and alpha
difference per scene is printed with a pass mark at ``--tolerance``. Gradients: the backend's
gradient of a random linear loss against central differences of the oracle, for the means,
colours and opacities of a small scene. Speed: forward and forward+backward of a 1M-Gaussian
1280x720 street-like scene (``bench_render.make_scene``), the backend under test next to the CPU
kernels (same process). The restorer: the pipeline's restoration on the device against the CPU's,
and one network evaluation's time on each. Exit status 1 when a check fails, 0 otherwise (3
without CUDA).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np
import torch

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from bench_render import make_scene  # noqa: E402

from symdrive_core.splat import rasterize, render_oracle  # noqa: E402


def random_scene(n, deg, seed, width=96, height=64, hard=False):
    """Gaussians in front of a camera at the origin; ``hard`` adds the cases renderers disagree on."""
    g = torch.Generator().manual_seed(seed)
    f64 = torch.float64
    means = torch.randn(n, 3, generator=g, dtype=f64) + torch.tensor([0.0, 0.0, 5.0], dtype=f64)
    quats = torch.randn(n, 4, generator=g, dtype=f64)
    scales = torch.exp(torch.randn(n, 3, generator=g, dtype=f64) * 0.5 - 2.5)
    opac = torch.sigmoid(torch.randn(n, generator=g, dtype=f64))
    colors = torch.randn(n, (deg + 1) ** 2, 3, generator=g, dtype=f64) * 0.5
    if hard:
        k = n // 6
        means[:k, 2] = torch.linspace(-0.5, 0.05, k, dtype=f64)  # behind and across the near plane
        scales[k:2 * k] = torch.tensor([3.0, 3.0, 3.0], dtype=f64)  # larger than the view
        scales[2 * k:3 * k, 0] = 1e-4  # needles
        opac[3 * k:4 * k] = 0.995  # above the clamp
        opac[4 * k:5 * k] = 1.2 / 255.0  # just above the threshold
    K = torch.tensor([[80.0, 0, width / 2 + 3], [0, 78.0, height / 2 - 2], [0, 0, 1.0]], dtype=f64)
    return [means, quats, scales, opac, colors, torch.eye(4, dtype=f64), K, width, height]


def agreement(backend, device, tolerance, quick):
    rows, ok = [], True
    cases = [(400, 0, 0, False), (400, 3, 1, False), (600, 3, 2, True)] + ([] if quick else [(3000, 3, 3, True)])
    for n, deg, seed, hard in cases:
        scene = random_scene(n, deg, seed, hard=hard)
        ref = render_oracle(*scene)
        args = [a.to(device=device, dtype=torch.float32) if torch.is_tensor(a) else a for a in scene]
        with torch.no_grad():
            rgb, alpha, _ = rasterize(*args, backend=backend)
        d_rgb = float(np.abs(rgb.double().cpu().numpy() - ref["rgb"]).max())
        d_alpha = float(np.abs(alpha.double().cpu().numpy() - ref["alpha"]).max())
        passed = bool(max(d_rgb, d_alpha) <= tolerance)
        ok &= passed
        rows.append({"gaussians": n, "sh_degree": deg, "hard_cases": hard, "max_rgb_diff": d_rgb,
                     "max_alpha_diff": d_alpha, "pass": passed})
        print(f"agreement  n={n:5d} deg={deg} hard={str(hard):5s}  max |rgb| {d_rgb:.2e}  max |alpha| "
              f"{d_alpha:.2e}  {'ok' if passed else 'FAIL'}")
    return rows, ok


def gradients(backend, device, tolerance, step=1e-6):
    """The backend's gradients against central differences of the float64 oracle."""
    scene = random_scene(60, 0, 7, width=40, height=32)
    weights = np.random.default_rng(0).normal(size=(32, 40, 3))

    def oracle_loss(values):
        return float((render_oracle(*values)["rgb"] * weights).sum())

    params = {0: "means", 3: "opacities", 4: "colors"}
    leaves = [a.to(device=device, dtype=torch.float32).requires_grad_(i in params) if torch.is_tensor(a) else a
              for i, a in enumerate(scene)]
    rgb, _, _ = rasterize(*leaves, backend=backend)
    (rgb * torch.as_tensor(weights, dtype=rgb.dtype, device=rgb.device)).sum().backward()
    rows, ok = [], True
    rng = np.random.default_rng(1)
    for i, name in params.items():
        grad = leaves[i].grad.double().cpu().numpy().reshape(-1)
        worst = 0.0
        for j in rng.choice(grad.size, size=6, replace=False):
            plus, minus = [a.clone() if torch.is_tensor(a) else a for a in scene], \
                          [a.clone() if torch.is_tensor(a) else a for a in scene]
            plus[i].view(-1)[j] += step
            minus[i].view(-1)[j] -= step
            fd = (oracle_loss(plus) - oracle_loss(minus)) / (2 * step)
            worst = max(worst, abs(fd - grad[j]) / max(1.0, abs(fd)))
        passed = bool(worst <= tolerance * 10)
        ok &= passed
        rows.append({"parameter": name, "worst_relative_error": worst, "pass": passed})
        print(f"gradient   {name:10s} worst relative error vs central differences {worst:.2e}  "
              f"{'ok' if passed else 'FAIL'}")
    return rows, ok


def speed(backend, device, n, width, height):
    out = {}
    for name, dev in ((backend, device), ("numba", torch.device("cpu"))):
        ps, viewmat, K = make_scene(n, width, height)
        ps = [p.to(dev).requires_grad_(True) for p in ps]
        viewmat, K = viewmat.to(dev), K.to(dev)

        def forward():
            with torch.no_grad():
                rasterize(*ps, viewmat, K, width, height, backend=name)
            if dev.type == "cuda":
                torch.cuda.synchronize()

        def forward_backward():
            rgb, _, _ = rasterize(*ps, viewmat, K, width, height, backend=name)
            rgb.sum().backward()
            if dev.type == "cuda":
                torch.cuda.synchronize()

        timings = {}
        for label, fn in (("forward_s", forward), ("forward_backward_s", forward_backward)):
            fn()  # warm-up: compilation, allocator
            t = time.perf_counter()
            fn()
            timings[label] = time.perf_counter() - t
        out[name] = timings
        print(f"speed      {name:6s} on {dev.type}: {n} Gaussians {width}x{height}  forward "
              f"{timings['forward_s']:.3f} s  forward+backward {timings['forward_backward_s']:.3f} s")
        if name == "numba" and backend == "numba":
            break
    if backend != "numba":
        for k in ("forward_s", "forward_backward_s"):
            out[f"cpu_over_{backend}_{k[:-2]}"] = out["numba"][k] / out[backend][k]
            print(f"speed      CPU kernels / {backend}, {k[:-2]}: {out[f'cpu_over_{backend}_{k[:-2]}']:.1f}x")
    return out


def restorer_check(device, quick: bool, tolerance_levels: float = 1.0) -> tuple[dict, bool]:
    """The pipeline's restoration on ``device`` against the CPU's: one noise-free guided-chain
    evaluation of a street-like frame (the image's largest difference in 8-bit levels; convolutions
    on CUDA may use TF32), and the seconds of one evaluation at 1920x1080 (960x540 with
    ``quick``) on each."""
    from bench_restorer_cpu import inputs

    from symdrive_core.diffusion.config import SAMPLERS
    from symdrive_core.diffusion.models import load_restorer
    from symdrive_core.diffusion.sampler import restore_image

    restorer = load_restorer().guided
    z, _, left, right, guide = inputs(256, 144, restorer.guide_channels)
    images = [(x * 0.5 + 0.5).clamp(0, 1) for x in (left, right, z / 0.8)]
    guide01 = guide * 0.5 + 0.5

    def restored(dev):
        restorer.to(dev)
        return restore_image(restorer, *images, SAMPLERS["builtin"], guide01)

    cpu_image = restored("cpu")
    diff = float((restored(device) - cpu_image).abs().max()) * 255
    w, h = (960, 540) if quick else (1920, 1080)
    big = inputs(w, h, restorer.guide_channels)
    seconds = {}
    for dev in dict.fromkeys(("cpu", str(device))):
        restorer.to(dev)
        args = [a.to(dev) for a in big]
        with torch.no_grad():
            restorer.net(*args)  # warm-up
            if dev.startswith("cuda"):
                torch.cuda.synchronize()
            t0 = time.perf_counter()
            restorer.net(*args)
            if dev.startswith("cuda"):
                torch.cuda.synchronize()
            seconds[dev] = round(time.perf_counter() - t0, 4)
    restorer.to("cpu")
    ok = diff <= tolerance_levels
    print(f"restorer on {device}: max difference from the CPU {diff:.3f} levels ({'pass' if ok else 'FAIL'}); "
          f"one evaluation at {w}x{h}: " + ", ".join(f"{d} {t:.3f} s" for d, t in seconds.items()))
    return {"max_diff_levels": round(diff, 4), "size": [w, h], "seconds": seconds}, ok


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--backend", choices=["gsplat", "numba", "torch"], default="gsplat",
                   help="backend under test (gsplat needs CUDA)")
    p.add_argument("--tolerance", type=float, default=2e-3, help="largest RGB/alpha difference that passes")
    p.add_argument("--quick", action="store_true", help="fewer scenes and a 100k-Gaussian 640x360 speed scene")
    p.add_argument("--json", help="also write the results to this file")
    args = p.parse_args(argv)
    if args.backend == "gsplat":
        if not torch.cuda.is_available():
            print("check_gpu: no CUDA device here: nothing checked (docs/renderer.md says where this ran)")
            return 3
        try:
            import gsplat  # noqa: F401
        except ImportError:
            print('check_gpu: gsplat is not installed: pip install -e ".[gpu]"')
            return 3
        device = torch.device("cuda")
    else:
        device = torch.device("cpu")
    print(f"backend {args.backend} on {device}; torch {torch.__version__}, {torch.get_num_threads()} CPU threads")
    agree, ok_a = agreement(args.backend, device, args.tolerance, args.quick)
    grads, ok_g = gradients(args.backend, device, args.tolerance)
    n, w, h = (100_000, 640, 360) if args.quick else (1_000_000, 1280, 720)
    timings = speed(args.backend, device, n, w, h)
    restoration, ok_r = restorer_check(device, args.quick)
    result = {"backend": args.backend, "device": str(device),
              "gpu": torch.cuda.get_device_name(0) if device.type == "cuda" else None,
              "agreement": agree, "gradients": grads, "speed": timings, "restorer": restoration,
              "pass": ok_a and ok_g and ok_r}
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=1)
    print("all checks pass" if result["pass"] else "SOME CHECKS FAIL")
    return 0 if result["pass"] else 1


if __name__ == "__main__":
    sys.exit(main())
