"""Time SUMO traffic against vehicle count, and rendering frames with that many vehicles.

Part 1: a straight two-lane road long enough that ``--density`` vehicles/km/lane gives N
vehicles at the start; SUMO simulates ``--seconds``; we time netconvert + SUMO + FCD reading +
pose resampling + the overlap check, median of ``--repeat`` runs.
Part 2 (when ``symdrive_core.splat.render.render_layers`` is available): each vehicle becomes a
synthetic ~4k-Gaussian SH-degree-3 asset; frames of the simulated traffic are rendered from an
elevated camera behind the traffic, vehicles only (no background), and timed per frame.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from symdrive_core.scene.road import Road
from symdrive_core.traffic.actors import traffic_actors
from symdrive_core.traffic.assets import Asset
from symdrive_core.traffic.overlap import check_actors
from symdrive_core.traffic.simulate import TrafficOptions, simulate

LANES = 2
FRAME_DT = 0.1


def traffic_run(n: int, args, seed: int, workdir: Path):
    length = max(30.0, n / (LANES * args.density / 1000.0))
    road = Road(np.array([[0.0, 0.0, 0.0], [length, 0.0, 0.0]]), LANES)
    assets = [Asset("car", workdir, np.array([1.8, 4.5, 1.5]), workdir / "splats.ply", None),
              Asset("van", workdir, np.array([2.0, 5.2, 1.9]), workdir / "splats.ply", None)]
    times = np.arange(args.frames) * FRAME_DT
    t0 = time.perf_counter()
    run = simulate(road, times, assets, TrafficOptions(args.density, args.seconds, seed), workdir)
    actors = traffic_actors(run.tracks, {a.name: a for a in assets}, road, times + run.time_offset, workdir)
    gaps = check_actors(actors, len(times))
    total = time.perf_counter() - t0
    return road, actors, run, gaps, total


def bench_sumo(args) -> dict:
    print(f"SUMO: straight {LANES}-lane road, {args.density:g} veh/km/lane, {args.seconds:g} s simulated "
          f"(step 0.1 s), median of {args.repeat}")
    print(f"{'vehicles':>8} {'road m':>7} {'simulated':>9} {'sumo s':>8} {'total s':>8} {'min gap m':>9}")
    kept = {}
    for n in args.counts:
        sumo_s, total_s = [], []
        for r in range(args.repeat):
            with tempfile.TemporaryDirectory() as tmp:
                road, actors, run, gaps, total = traffic_run(n, args, r, Path(tmp))
            sumo_s.append(run.sumo_seconds)
            total_s.append(total)
        kept[n] = (road, actors)
        print(f"{run.vehicles_at_start:>8} {road.length:>7.0f} {len(run.tracks):>9} {statistics.median(sumo_s):>8.3f} "
              f"{statistics.median(total_s):>8.3f} {gaps.min_gap if gaps.min_gap is not None else float('nan'):>9.3f}")
    return kept


def synthetic_vehicle(wlh, n: int, seed: int):
    import torch

    from symdrive_core.splat.tensors import GaussianTensors

    rng = np.random.default_rng(seed)
    half = 0.5 * np.array([wlh[1], wlh[0], wlh[2]])
    # points on the box surface: pick a face axis, push that coordinate to the face
    p = rng.uniform(-1.0, 1.0, size=(n, 3))
    axis = rng.integers(0, 3, n)
    p[np.arange(n), axis] = np.sign(p[np.arange(n), axis])
    sh = np.zeros((n, 16, 3))
    sh[:, 0] = rng.uniform(-1.0, 1.0, 3)
    sh[:, 1:] = 0.05 * rng.normal(size=(n, 15, 3))

    def t(a):
        return torch.as_tensor(a, dtype=torch.float32)

    return GaussianTensors(t(p * half), t(np.tile([1.0, 0, 0, 0], (n, 1))), t(np.full((n, 3), 0.06)),
                           t(np.full(n, 0.9)), t(sh), 3)


def bench_render(args, kept: dict) -> None:
    try:
        import torch

        from symdrive_core.splat.render import Layer, render_layers
    except ModuleNotFoundError as exc:
        print(f"\nrender: not measured ({exc})")
        return
    from symdrive_core import conventions

    torch.set_num_threads(args.threads)
    W, H = args.width, args.height
    K = torch.as_tensor(conventions.intrinsics_from_fov(W, H, np.radians(70.0)))
    print(f"\nrender: {W}x{H}, {args.gaussians} Gaussians per vehicle (SH 3), vehicles only, "
          f"{args.render_frames} frames, torch threads {args.threads}")
    print(f"{'vehicles':>8} {'drawn':>6} {'Gaussians':>10} {'s/frame':>8} {'backend':>8}")
    for n in [c for c in args.counts if c in args.render_counts]:
        road, actors = kept[n]
        assets = {}
        times = []
        drawn = 0
        for f in range(args.render_frames):
            layers = []
            for k, a in enumerate(actors):
                pose = a.poses[f]
                if pose is None:
                    continue
                key = tuple(a.wlh)
                if key not in assets:
                    assets[key] = synthetic_vehicle(a.wlh, args.gaussians, len(assets))
                layers.append(Layer(assets[key], torch.as_tensor(pose.R), torch.as_tensor(pose.translation), k + 1))
            eye = np.array([-15.0, 0.0, 12.0])
            target = np.array([0.4 * road.length, 0.0, 0.0])
            c2w = look_at(eye, target)
            viewmat = torch.as_tensor(conventions.invert_rigid(c2w))
            t0 = time.perf_counter()
            out = render_layers(layers, viewmat, K, W, H)
            times.append(time.perf_counter() - t0)
            drawn = len(layers) - len(out["culled"])
        backend = out["info"].get("backend", "?")
        print(f"{n:>8} {drawn:>6} {drawn * args.gaussians:>10} {statistics.median(times):>8.3f} {backend:>8}")


def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    z = target - eye
    z = z / np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    c2w = np.eye(4)
    c2w[:3, 0], c2w[:3, 1], c2w[:3, 2], c2w[:3, 3] = x, np.cross(z, x), z, eye
    return c2w


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--counts", type=int, nargs="+", default=[5, 10, 25, 50, 100])
    ap.add_argument("--render-counts", type=int, nargs="+", default=[5, 10, 25, 50])
    ap.add_argument("--density", type=float, default=40.0)
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--gaussians", type=int, default=4096)
    ap.add_argument("--width", type=int, default=480)
    ap.add_argument("--height", type=int, default=270)
    ap.add_argument("--render-frames", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--no-render", action="store_true")
    args = ap.parse_args()
    kept = bench_sumo(args)
    if not args.no_render:
        bench_render(args, kept)


if __name__ == "__main__":
    main()
