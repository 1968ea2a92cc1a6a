"""The demo street written as COLMAP, nerfstudio and 3DGS-trainer outputs after a similarity
transform of its world, for the importers' round-trip tests."""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from symdrive_core.gaussians import Gaussians
from symdrive_core.importers.similarity import (
    apply_camera,
    apply_points,
    make_similarity,
    transform_gaussians,
)
from symdrive_core.io.ply import read_splats, write_splats
from symdrive_core.io.points import read_points, write_points
from symdrive_core.rotations import quat_normalize, quat_to_matrix
from symdrive_core.scene import load_manifest

DEMO = Path(__file__).resolve().parents[2] / "symdrive_core" / "data" / "demo_street"
CAMERA_HEIGHT = 1.6  # the demo camera's height above the road, metres


@dataclass
class World:
    """The demo's cameras, splats and points in a source frame: x_src = S x_demo."""

    S: np.ndarray
    names: list[str]
    images: list[Path]
    K: np.ndarray
    width: int
    height: int
    c2w: np.ndarray  # [N, 4, 4] OpenCV, source frame
    c2w_demo: np.ndarray
    splats: Gaussians | None
    points: np.ndarray
    colors: np.ndarray


def random_similarity(seed: int, scale: float = 0.37, offset_m: float = 1000.0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    R = quat_to_matrix(quat_normalize(rng.normal(size=4)))
    d = rng.normal(size=3)
    return make_similarity(scale, R, scale * offset_m * d / np.linalg.norm(d))


_CACHE: dict = {}


def demo_splats(max_splats: int | None = 12000) -> Gaussians:
    """The demo's background splats nearest the camera path (a subset keeps renders fast)."""
    key = ("splats", max_splats)
    if key not in _CACHE:
        g = read_splats(DEMO / "reconstruction" / "background.ply")
        if max_splats is not None and len(g) > max_splats:
            m = load_manifest(DEMO)
            c = np.array([f.camera_to_world[:3, 3] for f in m.cameras[0].frames])
            d = np.min(np.linalg.norm(g.means[:, None, :2] - c[None, :, :2], axis=-1), axis=1)
            g = g.subset(np.sort(np.argsort(d)[:max_splats]))
        _CACHE[key] = g
    return _CACHE[key]


def demo_world(seed: int = 0, max_splats: int | None = 12000) -> World:
    m = load_manifest(DEMO)
    cam = m.cameras[0]
    S = random_similarity(seed)
    c2w_demo = np.stack([f.camera_to_world for f in cam.frames])
    pts, cols = read_points(DEMO / "background" / "points.ply")
    return World(
        S=S,
        names=[f"{i:06d}.png" for i in range(len(cam.frames))],
        images=[m.resolve(f.image) for f in cam.frames],
        K=cam.frames[0].K.copy(), width=cam.width, height=cam.height,
        c2w=np.stack([apply_camera(S, c) for c in c2w_demo]), c2w_demo=c2w_demo,
        splats=transform_gaussians(demo_splats(max_splats), S),
        points=apply_points(S, pts), colors=cols.astype(np.float64),
    )


def link_images(world: World, folder: Path, names: list[str] | None = None) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for name, src in zip(names or world.names, world.images):
        dst = folder / name
        dst.parent.mkdir(parents=True, exist_ok=True)
        try:
            os.link(src, dst)
        except OSError:
            shutil.copy2(src, dst)
    return folder


def write_colmap(world: World, model: Path, *, binary: bool = True, model_name: str = "PINHOLE",
                 with_points: bool = True, params: list[float] | None = None) -> Path:
    """``params`` default to the world's K as PINHOLE or SIMPLE_PINHOLE parameters."""
    from symdrive_core.importers.colmap import load_pycolmap

    pycolmap = load_pycolmap()
    rec = pycolmap.Reconstruction()
    fx, fy, cx, cy = world.K[0, 0], world.K[1, 1], world.K[0, 2], world.K[1, 2]
    if params is None:
        params = [fx, fy, cx, cy] if model_name == "PINHOLE" else [fx, cx, cy]
    rec.add_camera_with_trivial_rig(pycolmap.Camera(camera_id=1, model=model_name, width=world.width,
                                                    height=world.height, params=params))
    for i, (name, c2w) in enumerate(zip(world.names, world.c2w), start=1):
        w2c = np.linalg.inv(c2w)
        rec.add_image_with_trivial_frame(pycolmap.Image(image_id=i, name=name, camera_id=1),
                                         pycolmap.Rigid3d(w2c[:3, :4]))
    if with_points:
        cols = np.rint(np.clip(world.colors, 0, 1) * 255).astype(np.uint8)
        for p, c in zip(world.points, cols):
            rec.add_point3D(p, pycolmap.Track(), c)
    model.mkdir(parents=True, exist_ok=True)
    (rec.write_binary if binary else rec.write_text)(str(model))
    return model


GL = np.diag([1.0, -1.0, -1.0, 1.0])  # OpenCV camera axes <-> OpenGL camera axes


def write_nerfstudio(world: World, folder: Path, *, applied: np.ndarray | None = None, per_frame: bool = False,
                     timestamps: bool = False, with_points: bool = True) -> Path:
    """transforms.json beside images/, poses as ``applied @ c2w_opengl`` (nerfstudio's
    ``applied_transform`` convention), points and splats (when the world has them) in that frame too.
    ``with_points=False``: poses only (no ``ply_file_path``)."""
    A = np.eye(4) if applied is None else applied
    link_images(world, folder / "images")
    intr = {"fl_x": world.K[0, 0], "fl_y": world.K[1, 1], "cx": world.K[0, 2], "cy": world.K[1, 2],
            "w": world.width, "h": world.height}
    frames = []
    for i, (name, c2w) in enumerate(zip(world.names, world.c2w)):
        f = {"file_path": f"images/{name}", "transform_matrix": (A @ c2w @ GL).tolist()}
        if per_frame:
            f.update(intr)
        if timestamps:
            f["timestamp"] = 100.0 + 0.05 * i
        frames.append(f)
    rng = np.random.default_rng(1)
    frames = [frames[i] for i in rng.permutation(len(frames))]  # order must come from names/times
    data = {"camera_model": "OPENCV", "k1": 0.0, "k2": 0.0, "p1": 0.0, "p2": 0.0, "frames": frames}
    if not per_frame:
        data.update(intr)
    if applied is not None:
        data["applied_transform"] = A[:3].tolist()
    if with_points:
        write_points(folder / "sparse_pc.ply", apply_points(A, world.points), world.colors)
        data["ply_file_path"] = "sparse_pc.ply"
    (folder / "transforms.json").write_text(json.dumps(data, indent=1))
    if world.splats is not None:
        write_splats(folder / "splat.ply", transform_gaussians(world.splats, A))
    return folder / "transforms.json"


def write_gs_output(world: World, model: Path, images: Path, *, iterations=(7000, 30000)) -> Path:
    """The original 3DGS trainer's output folder: cameras.json, cfg_args, point_cloud/iteration_*/."""
    link_images(world, images)
    cams = []
    for i, (name, c2w) in enumerate(zip(world.names, world.c2w)):
        cams.append({"id": i, "img_name": Path(name).stem, "width": world.width, "height": world.height,
                     "position": c2w[:3, 3].tolist(), "rotation": c2w[:3, :3].tolist(),
                     "fy": world.K[1, 1], "fx": world.K[0, 0]})
    model.mkdir(parents=True, exist_ok=True)
    (model / "cameras.json").write_text(json.dumps(cams))
    (model / "cfg_args").write_text(
        f"Namespace(data_device='cuda', eval=False, images='images', model_path={str(model)!r}, "
        f"resolution=-1, sh_degree=3, source_path={str(images.parent)!r}, white_background=False)")
    write_points(model / "input.ply", world.points, world.colors)  # the trainer's copy of its SfM points
    for it in iterations:
        g = world.splats if it == max(iterations) else world.splats.subset(np.arange(10))
        write_splats(model / "point_cloud" / f"iteration_{it}" / "point_cloud.ply", g)
    return model
