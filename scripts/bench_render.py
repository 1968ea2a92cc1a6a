"""Benchmark the CPU splat rasterizer against the vectorised torch reference in the same process.

    python scripts/bench_render.py --quick            # ~1 minute subset
    python scripts/bench_render.py --json out.json    # everything (several minutes)

Reports today's frame against the baseline frame (``symdrive_core.bench.rasterize_baseline``: the
pixel-outer kernels of ``kernels_baseline`` and the shared path as it was), same scene, same thread
count, alternating runs: the whole forward and forward+backward, the part outside the compositing
kernels and the kernels alone, with the ratios; the first
demo-street frame of a fresh process (numba cache warm); forward and forward+backward times vs
Gaussian count and resolution (numba kernels next to the pure-torch reference, with the ratio),
tile-Gaussian intersections per second, peak RSS of a
1M-Gaussian 1280x720 render (measured in a fresh subprocess), the vehicle-count table (5/10/25/50
vehicles on a large background) and accuracy-vs-time knobs against the float64 oracle. The load
average is printed too: other processes on the machine slow multi-threaded timings down.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import resource
import subprocess
import sys
import time

import numba
import numpy as np
import torch

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from symdrive_core.bench import kernels_baseline
from symdrive_core.bench.rasterize_baseline import rasterize_baseline
from symdrive_core.splat import (
    GaussianTensors,
    Layer,
    kernels,
    rasterize,
    render_layers,
    render_oracle,
)


def make_scene(n, width, height, seed=0, deg=3, dtype=torch.float32, fov_deg=70.0):
    """A street-like random cloud filling the view from 4 m to 44 m."""
    g = torch.Generator().manual_seed(seed)
    z = 4 + 40 * torch.rand(n, generator=g, dtype=torch.float64)
    tx = math.tan(math.radians(fov_deg) / 2)
    ty = tx * height / width
    x = (torch.rand(n, generator=g, dtype=torch.float64) * 2 - 1) * z * tx * 1.1
    y = (torch.rand(n, generator=g, dtype=torch.float64) * 2 - 1) * z * ty * 1.1
    means = torch.stack([x, y, z], 1)
    quats = torch.randn(n, 4, generator=g, dtype=torch.float64)
    # footprint of a few pixels whatever the resolution (like a trained scene of this density)
    px = 0.5 * width / tx
    scales = torch.exp(torch.randn(n, 3, generator=g, dtype=torch.float64) * 0.5) * z[:, None] * (
        2.2 * math.sqrt(640 * 360 / n) * (width / 640) / px)
    opac = torch.sigmoid(torch.randn(n, generator=g, dtype=torch.float64) + 0.5)
    sh = torch.randn(n, (deg + 1) ** 2, 3, generator=g, dtype=torch.float64) * 0.3
    K = torch.tensor([[px, 0, width / 2], [0, px, height / 2], [0, 0, 1.0]], dtype=torch.float64)
    ps = [t.to(dtype) for t in (means, quats, scales, opac, sh)]
    return ps, torch.eye(4, dtype=dtype), K.to(dtype)


def timeit(fn, repeat=3, budget_s=20.0, warmup=True):
    if warmup:
        fn()  # warm-up (compilation, allocator)
    best, spent = float("inf"), 0.0
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        dt = time.perf_counter() - t
        best, spent = min(best, dt), spent + dt
        if spent > budget_s:
            break
    return best, out


def run_case(n, width, height, backend, backward, deg=3, **kw):
    """Best time of a few runs (numba: after a warm-up; the slow reference: a single run)."""
    ps, V, K = make_scene(n, width, height, deg=deg)

    def fwd():
        with torch.no_grad():
            return rasterize(*ps, V, K, width, height, backend=backend, **kw)

    def fwd_bwd():
        leaf = [p.detach().requires_grad_(True) for p in ps]
        rgb, alpha, info = rasterize(*leaf, V, K, width, height, backend=backend, **kw)
        (rgb.sum() + alpha.sum()).backward()
        return rgb, alpha, info

    if backend == "torch":
        return timeit(fwd_bwd if backward else fwd, repeat=1, warmup=False)
    return timeit(fwd_bwd if backward else fwd, repeat=3 if backward else 5)


def row(label, t_numba, t_ref):
    ratio = f"{t_ref / t_numba:7.1f}x" if t_ref else "      -"
    ref = f"{t_ref * 1000:10.1f}" if t_ref else "         -"
    return f"{label:>24} {t_numba * 1000:10.1f} {ref} {ratio}"


def bench_counts(counts, res, ref_max, results, ref_bwd_max=None):
    ref_bwd_max = ref_max if ref_bwd_max is None else ref_bwd_max
    W, H = res
    print(f"\n## Gaussian count sweep at {W}x{H} (ms; ratio = reference / numba)")
    print(f"{'case':>24} {'numba':>10} {'reference':>10} {'ratio':>8}   isect   isect/s(fwd)")
    for n in counts:
        for backward in (False, True):
            tn, (rgb, alpha, info) = run_case(n, W, H, "numba", backward)
            tr = run_case(n, W, H, "torch", backward)[0] if n <= (ref_bwd_max if backward else ref_max) else None
            label = f"{n:>8} {'fwd+bwd' if backward else 'fwd'}"
            print(row(label, tn, tr), f"{info['n_isect']:>8} {info['n_isect'] / tn:12.3e}", flush=True)
            results.append({"table": "count", "n": n, "width": W, "height": H, "backward": backward,
                            "numba_s": tn, "reference_s": tr, "ratio": tr / tn if tr else None,
                            "n_isect": info["n_isect"], "isect_per_s": info["n_isect"] / tn})


def bench_resolutions(n, resolutions, ref_max_pixels, results):
    print(f"\n## Resolution sweep at {n} Gaussians (ms)")
    print(f"{'case':>24} {'numba':>10} {'reference':>10} {'ratio':>8}   isect   isect/s(fwd)")
    for W, H in resolutions:
        for backward in (False, True):
            tn, (rgb, alpha, info) = run_case(n, W, H, "numba", backward)
            tr = run_case(n, W, H, "torch", backward)[0] if W * H <= ref_max_pixels else None
            label = f"{W}x{H} {'fwd+bwd' if backward else 'fwd'}"
            print(row(label, tn, tr), f"{info['n_isect']:>8} {info['n_isect'] / tn:12.3e}", flush=True)
            results.append({"table": "resolution", "n": n, "width": W, "height": H, "backward": backward,
                            "numba_s": tn, "reference_s": tr, "ratio": tr / tn if tr else None,
                            "n_isect": info["n_isect"], "isect_per_s": info["n_isect"] / tn})


@contextlib.contextmanager
def timed_kernels(module, spent):
    """Time ``module``'s compositing kernels: ``spent`` gets each call's wall and CPU seconds (``fwd``,
    ``fwd_cpu``, ``bwd``, ``bwd_cpu``; CPU time of all threads: the work, whatever else runs)."""
    saved = module.rasterize_fwd, module.rasterize_bwd

    def timed(name, fn):
        def call(*args):
            t, c = time.perf_counter(), time.process_time()
            fn(*args)
            spent[name] = time.perf_counter() - t
            spent[name + "_cpu"] = time.process_time() - c
        return call

    module.rasterize_fwd = timed("fwd", saved[0])
    module.rasterize_bwd = timed("bwd", saved[1])
    try:
        yield
    finally:
        module.rasterize_fwd, module.rasterize_bwd = saved


def bench_baseline(n, res, results, repeat=3):
    """Today's frame against the baseline frame: alternating runs, best of ``repeat`` each.

    The baseline frame is :func:`rasterize_baseline` (the pixel-outer compositing kernels and the
    shared path as it was: torch gathers and index-put backward, serial gradient reduction, binning
    from index-ordered rectangles); the current one is :func:`rasterize`. Both use the same projection
    and SH kernels. ``shared`` is the frame's time outside the compositing kernels.
    """
    W, H = res
    ps, V, K = make_scene(n, W, H)
    print(f"\n## Whole frame and compositing kernels vs the baseline: {n} Gaussians, {W}x{H}, "
          f"{numba.get_num_threads()} threads (s, best of {repeat}; ratio = baseline / current)")
    print(f"{'case':>8} {'frame base':>10} {'cur':>6} {'ratio':>6}   {'shared base':>11} {'cur':>6} {'ratio':>6}   "
          f"{'kernels base':>12} {'cur':>6} {'ratio':>6}   {'kernel CPU base':>15} {'cur':>6} {'ratio':>6}")
    frames = {"baseline": (kernels_baseline, rasterize_baseline), "current": (kernels, rasterize)}
    for backward in (False, True):
        def run(fn):
            if not backward:
                with torch.no_grad():
                    return fn(*ps, V, K, W, H)
            leaf = [p.detach().requires_grad_(True) for p in ps]
            out = fn(*leaf, V, K, W, H)
            (out[0].sum() + out[1].sum()).backward()
            return out

        best = {name: [math.inf] * 4 for name in frames}  # whole, shared, kernels, kernels' CPU
        for rep in range(repeat + 1):  # the first round compiles and warms up
            for name, (module, fn) in frames.items():
                spent = {}
                with timed_kernels(module, spent):
                    t = time.perf_counter()
                    run(fn)
                    dt = time.perf_counter() - t
                if rep:
                    wall = sum(v for k, v in spent.items() if not k.endswith("_cpu"))
                    cpu = sum(v for k, v in spent.items() if k.endswith("_cpu"))
                    best[name] = [min(b, v) for b, v in zip(best[name], (dt, dt - wall, wall, cpu))]
        (bw, bs, bk, bc), (cw, cs, ck, cc) = best["baseline"], best["current"]
        label = "fwd+bwd" if backward else "fwd"
        print(f"{label:>8} {bw:10.3f} {cw:6.3f} {bw / cw:5.2f}x   {bs:11.3f} {cs:6.3f} {bs / cs:5.2f}x   "
              f"{bk:12.3f} {ck:6.3f} {bk / ck:5.2f}x   {bc:15.3f} {cc:6.3f} {bc / cc:5.2f}x", flush=True)
        results.append({"table": "baseline", "n": n, "width": W, "height": H, "backward": backward,
                        "threads": numba.get_num_threads(), "baseline_s": bw, "current_s": cw, "ratio": bw / cw,
                        "baseline_shared_s": bs, "current_shared_s": cs, "shared_ratio": bs / cs,
                        "baseline_kernel_s": bk, "current_kernel_s": ck, "kernel_ratio": bk / ck,
                        "baseline_kernel_cpu_s": bc, "current_kernel_cpu_s": cc, "kernel_cpu_ratio": bc / cc})


FIRST_FRAME = """
import time
t0 = time.perf_counter()
from symdrive_core.world.demo import DEMO_PACKAGE
from symdrive_core.pipeline.preview import preview_manifest
from symdrive_core.pipeline.scene_render import SceneRenderer
from symdrive_core.scene import load_manifest
t1 = time.perf_counter()
renderer = SceneRenderer(preview_manifest(load_manifest(DEMO_PACKAGE), "front"), device="cpu")
renderer.render("front", 0)
t2 = time.perf_counter()
renderer.render("front", 1)
t3 = time.perf_counter()
print(t1 - t0, t2 - t1, t3 - t2)
"""


def bench_first_frame(results):
    """The demo street's first frame in fresh processes: once to fill numba's cache, then timed."""
    root = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
    env = {**os.environ, "PYTHONPATH": os.path.abspath(root)}
    runs = []
    for _ in range(3):
        done = subprocess.run([sys.executable, "-c", FIRST_FRAME], capture_output=True, text=True, check=True,
                              env=env)
        runs.append([float(v) for v in done.stdout.split()] + ["compiling" in done.stderr])
    imports, first, second, compiled = runs[-1]
    print(f"\n## Demo street, fresh process, numba cache warm: imports {imports:.2f} s, first frame {first:.2f} s, "
          f"second frame {second:.2f} s (first process compiled: {runs[0][3]}, "
          f"first frame {runs[0][1]:.2f} s)")
    results.append({"table": "first_frame", "imports_s": imports, "first_frame_s": first, "second_frame_s": second,
                    "compiled_in_first_process": runs[0][3], "first_process_first_frame_s": runs[0][1]})


def rss_child(n, width, height):
    ps, V, K = make_scene(n, width, height)
    with torch.no_grad():
        t = time.perf_counter()
        rgb, alpha, info = rasterize(*ps, V, K, width, height)
        dt = time.perf_counter() - t
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 ** 2  # KiB -> GiB
    print(json.dumps({"n": n, "width": width, "height": height, "peak_rss_gib": peak, "forward_s": dt,
                      "n_isect": info["n_isect"]}))


def bench_rss(n, width, height, results):
    out = subprocess.run([sys.executable, os.path.abspath(__file__), "--rss-child", str(n), str(width), str(height)],
                         capture_output=True, text=True, check=True).stdout.strip().splitlines()[-1]
    r = json.loads(out)
    print(f"\n## Peak RSS: {n} Gaussians at {width}x{height}: {r['peak_rss_gib']:.2f} GiB "
          f"(fresh process, scene creation included; first forward {r['forward_s']:.2f} s incl. load)")
    results.append({"table": "rss", **r})


def make_vehicle(n, seed):
    rng = np.random.default_rng(seed)
    # points on a 4.5 x 1.8 x 1.5 m box surface, small flat Gaussians
    p = rng.uniform(-1, 1, size=(n, 3)) * np.array([2.25, 0.9, 0.75])
    axis = rng.integers(0, 3, n)
    p[np.arange(n), axis] = np.sign(p[np.arange(n), axis]) * np.array([2.25, 0.9, 0.75])[axis]
    s = np.full((n, 3), 0.03 * math.sqrt(4000 / n) * 1.5)
    s[np.arange(n), axis] *= 0.1
    k = 16
    return GaussianTensors(torch.tensor(p, dtype=torch.float32), torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1),
                           torch.tensor(s, dtype=torch.float32), torch.full((n,), 0.9),
                           torch.tensor(rng.normal(size=(n, k, 3)) * 0.3, dtype=torch.float32), 3)


def bench_vehicles(bg_n, sizes, counts, res, results):
    W, H = res
    ps, V, K = make_scene(bg_n, W, H)
    bg = GaussianTensors(ps[0], ps[1], ps[2], ps[3], ps[4], 3)
    # camera at the origin looking down +z (OpenCV); road = x across, vehicles spread ahead
    print(f"\n## Vehicle count: background {bg_n} Gaussians, {W}x{H}, forward through render_layers (ms)")
    print(f"{'vehicle size':>14} " + " ".join(f"{c:>8}" for c in counts) + "   slowdown 5->50")
    for size in sizes:
        car = make_vehicle(size, 1)
        times = []
        for c in counts:
            layers = [Layer(bg, None, None, 0)]
            for i in range(c):
                lane, row_ = i % 5, i // 5
                yaw = 0.3 * (i % 7)
                R = torch.tensor([[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0], [0, 0, 1.0]])
                T = torch.tensor([(lane - 2) * 3.5, 1.2, 8.0 + 4.0 * row_])
                layers.append(Layer(car, R, T, i + 1))

            def f():
                with torch.no_grad():
                    return render_layers(layers, V, K, W, H)

            t, out = timeit(f, repeat=2)
            times.append(t)
            results.append({"table": "vehicles", "background": bg_n, "vehicle_size": size, "vehicles": c,
                            "width": W, "height": H, "forward_s": t, "n_isect": out["info"]["n_isect"],
                            "culled": len(out["culled"])})
        slow = times[-1] / times[0]
        print(f"{size:>14} " + " ".join(f"{t * 1000:8.0f}" for t in times) + f"   {slow:6.2f}x", flush=True)
        results.append({"table": "vehicles_slowdown", "vehicle_size": size, "slowdown": slow,
                        "from": counts[0], "to": counts[-1]})


def bench_knobs(n, res, results):
    W, H = res
    ps64, V, K = make_scene(n, W, H, dtype=torch.float64, seed=3)
    base = render_oracle(*ps64, V.double(), K.double(), W, H)["rgb"]
    print(f"\n## Accuracy vs time knobs: {n} Gaussians, {W}x{H}; max |rgb - oracle| of the same setting"
          " and of the exact default (float64, classic, SH 3, opacity extent, threshold 1/255)")
    print(f"{'setting':>24} {'fwd ms':>8} {'fwd+bwd ms':>10} {'err same':>10} {'err default':>11}")
    configs = [("default float32", {}, torch.float32, 3), ("float64", {}, torch.float64, 3),
               ("antialiased", {"antialiased": True}, torch.float32, 3),
               ("3sigma extent", {"extent": "3sigma"}, torch.float32, 3),
               ("alpha thr 1/50", {"alpha_threshold": 1 / 50}, torch.float32, 3),
               ("alpha thr 1/1000", {"alpha_threshold": 1e-3}, torch.float32, 3)]
    configs += [(f"SH degree {d}", {"sh_degree": d}, torch.float32, d) for d in (0, 1, 2)]
    for label, kw, dtype, deg in configs:
        ps = [p.to(dtype) for p in ps64]
        Vd, Kd = V.to(dtype), K.to(dtype)

        def f():
            with torch.no_grad():
                return rasterize(*ps, Vd, Kd, W, H, **kw)

        def fb():
            leaf = [p.detach().requires_grad_(True) for p in ps]
            rgb, alpha, _ = rasterize(*leaf, Vd, Kd, W, H, **kw)
            (rgb.sum() + alpha.sum()).backward()

        t, (rgb, _, _) = timeit(f)
        tb, _ = timeit(fb, repeat=2)
        same = render_oracle(*ps64, V.double(), K.double(), W, H, **kw)["rgb"]
        e_same = float(np.abs(rgb.double().numpy() - same).max())
        e_def = float(np.abs(rgb.double().numpy() - base).max())
        print(f"{label:>24} {t * 1000:8.1f} {tb * 1000:10.1f} {e_same:10.2e} {e_def:11.2e}", flush=True)
        results.append({"table": "knobs", "setting": label, "forward_s": t, "forward_backward_s": tb,
                        "max_err_same_setting": e_same, "max_err_vs_default": e_def})


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small subset (~1 minute)")
    ap.add_argument("--json", help="write all numbers to this file")
    ap.add_argument("--threads", type=int, default=0, help="torch and numba threads (default: all cores)")
    ap.add_argument("--only", default="", help="comma list of: baseline,first,counts,res,rss,vehicles,knobs")
    ap.add_argument("--counts", default="", help="comma list overriding the count sweep (e.g. 100000)")
    ap.add_argument("--vehicle-sizes", default="", help="comma list overriding the vehicle sizes (e.g. 4000)")
    ap.add_argument("--background", type=int, default=0, help="background Gaussians of the vehicle table")
    ap.add_argument("--rss-child", nargs=3, type=int, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.threads:
        import numba
        torch.set_num_threads(args.threads)
        numba.set_num_threads(args.threads)
    if args.rss_child:
        rss_child(*args.rss_child)
        return
    only = set(filter(None, args.only.split(",")))
    want = lambda k: not only or k in only
    print(f"# bench_render: cores={os.cpu_count()} torch threads={torch.get_num_threads()} "
          f"load average={os.getloadavg()[0]:.2f} quick={args.quick}")
    results = []
    t0 = time.time()
    if want("baseline"):
        bench_baseline(*((100_000, (640, 360)) if args.quick else (1_000_000, (1280, 720))), results)
    if want("first"):
        bench_first_frame(results)
    if args.quick:
        if want("counts"):
            bench_counts([1_000, 10_000, 100_000], (320, 180), 10_000, results, ref_bwd_max=1_000)
        if want("res"):
            bench_resolutions(30_000, [(320, 180), (1280, 720)], 0, results)
        if want("vehicles"):
            bench_vehicles(100_000, [4_000], [5, 50], (640, 360), results)
        if want("knobs"):
            bench_knobs(200, (160, 90), results)
    else:
        if want("counts"):
            counts = [int(c) for c in args.counts.split(",")] if args.counts else [1_000, 10_000, 100_000, 1_000_000]
            bench_counts(counts, (640, 360), 100_000, results)
        if want("res"):
            bench_resolutions(100_000, [(320, 180), (640, 360), (1280, 720), (1920, 1080)], 640 * 360, results)
        if want("rss"):
            bench_rss(1_000_000, 1280, 720, results)
        if want("vehicles"):
            sizes = [int(c) for c in args.vehicle_sizes.split(",")] if args.vehicle_sizes else [4_000, 100_000]
            bench_vehicles(args.background or 1_000_000, sizes, [5, 10, 25, 50], (1280, 720), results)
        if want("knobs"):
            bench_knobs(1_000, (320, 180), results)
    print(f"\n# total {time.time() - t0:.0f} s, load average now {os.getloadavg()[0]:.2f}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"load_average": os.getloadavg()[0], "quick": args.quick, "results": results}, fh, indent=1)


if __name__ == "__main__":
    main()
