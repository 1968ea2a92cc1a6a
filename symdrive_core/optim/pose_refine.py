"""Tracked vehicles' poses refined with their Gaussians (as Street Gaussians optimises its tracks).

A tracker's boxes are off by decimetres and degrees from frame to frame, and a vehicle fitted in
boxes that jitter smears just as a static fit does. So each tracked vehicle's pose at frame ``f``
gets a learnt correction, zero at the start::

    T_f = T_track_f + dt_f          (metres, in the world)
    R_f = Rz(dpsi_f) R_track_f      (yaw about the world's up, about the box centre)

fitted jointly with the Gaussians (the rendered image's gradient reaches it through
:mod:`symdrive_core.splat.compose`), under two priors:

* **towards the track**: ``|dt_f|^2 / prior_m^2 + dpsi_f^2 / prior_rad^2``: the boxes are right on
  average, and without this a shift of every box could be traded for a shift of the Gaussians;
* **smooth in time**: the second difference of the *refined* trajectory (centres, and the yaw
  unwrapped along the track), ``|T_{f+1} - 2 T_f + T_{f-1}|^2 / smooth_m^2`` and the same of the yaw
  over ``smooth_rad^2``: a car's motion is smooth from frame to frame, a tracker's error is not. A
  frame without an image (held out) is placed by this term alone, between its neighbours.
  ``smooth_order`` 3 smooths the third difference (jerk) instead, which a steady lane change or
  turn does not pay; measured on jittered boxes it frees a lane-changing car and loosens the
  hold on straight ones about as much (docs/results.md), so 2 stays the default;
* **a car moves where it points** (``slip_m``): the sideways part of the move between consecutive
  frames, ``|(T_{f+1} - T_f) x h((psi_f + psi_{f+1}) / 2)|^2 / slip_m^2`` with ``h`` the heading's
  horizontal unit vector, as a unicycle model has it: the heading is then tied to the path, and a
  tracker's heading error (degrees, per frame) to the path's direction over many frames.

The scales ``prior_m`` and ``smooth_m`` (and their yaw twins) are by default estimated from each
track itself (:mod:`.track_noise`: how much its boxes jitter, how smoothly its vehicle moves), so a
car holding its lane is held to a line and one changing lanes is let change them. A heading set by
hand (one number for a whole track, as KITTI's labels have it) is smooth and can still be degrees
off its path; with the slip, the heading's error scale is at least its angle to the track's
chords (``heading_chord_m``), so the slip turns such a heading onto the path rather than drag the
path after it.

The smoothness links consecutive frames of one *piece* of a track only: a frame without a box, or
a frame the tracks import reported (a jump, a turn or a size change between consecutive boxes,
a re-entry into the images: ``source.tracks.reported``), starts a new piece, so a jump is never
smoothed into a motion (which would drag the right boxes beside it metres towards the wrong one).

Every training step adds the priors, and each view's photometric loss comes once per pass over
the views, so the priors are divided by the number of training views: over a pass each counts
once. The corrections start after ``start_fraction`` of the iterations, when the vehicle's
Gaussians look like it (before, they are a box of the colours the frames show there).
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from ..io.atomic import atomic_path, write_text_atomic
from ..rotations import matrix_to_quat
from ..scene import Manifest
from ..scene.poses import Pose, yaw_of
from .config import PoseRefineConfig
from .track_noise import estimate_scales, heading_disagreement

POSES_FILE = "poses.json"  # the refined poses, beside the reconstruction's actors/<id>.ply


def tracked_actors(manifest: Manifest) -> set[str]:
    """Ids of the actors whose boxes came from tracks (``import tracks``' record in ``source.tracks``)."""
    return set(manifest.source.get("tracks", {}).get("actors", []))


def reported_frames(manifest: Manifest, actor_id: str) -> set[int]:
    """The frames the tracks import reported for ``actor_id``: where its trajectory is cut."""
    return {r["frame"] for r in manifest.source.get("tracks", {}).get("reported", []) if r["actor"] == actor_id}


def refined_actors(manifest: Manifest, cfg: PoseRefineConfig, candidates: list[str]) -> list[str]:
    """Which of ``candidates`` (recorded vehicles being fitted) get pose corrections."""
    if cfg.enabled is None:
        tracked = tracked_actors(manifest)
        return [a for a in candidates if a in tracked]
    return list(candidates) if cfg.enabled else []


def track_boxes(manifest: Manifest, actor_id: str) -> list[Pose | None]:
    """The boxes a refinement starts from and is pulled towards: the tracks' (``tracked_poses``,
    when an earlier refinement was written back), else the recorded poses."""
    a = manifest.actor(actor_id)
    return list(a.tracked_poses) if a.tracked_poses is not None else [a.recorded_pose(f) for f in range(len(a.poses))]


def pieces(frames: list[int], cuts: set[int]) -> list[list[int]]:
    """``frames`` (increasing) split into runs of consecutive frames, a new run at each frame of
    ``cuts``."""
    out: list[list[int]] = []
    for f in frames:
        if out and f == out[-1][-1] + 1 and f not in cuts:
            out[-1].append(f)
        else:
            out.append([f])
    return out


def track_scales(centres: np.ndarray, yaw: np.ndarray, runs: list[list[int]], cfg: PoseRefineConfig) -> dict:
    """The priors' scales for one track (``prior_m``, ``smooth_m``, ``prior_rad``, ``smooth_rad``):
    estimated from its horizontal centres and unwrapped yaw along its pieces (rows ``runs``) with
    ``cfg.scales_from_track``, else (or where its pieces are too short) the configured ones; with
    the slip, the heading's error is at least its angle to the track's own path (a hand-set
    heading can be degrees off and smooth)."""
    out = {"prior_m": cfg.prior_m, "smooth_m": cfg.smooth_m, "prior_rad": cfg.prior_rad, "smooth_rad": cfg.smooth_rad}
    if not cfg.scales_from_track:
        return out
    xy = estimate_scales([centres[run, :2] for run in runs], cfg.smooth_order, cfg.smooth_floor_m, cfg.noise_floor_m)
    turn = estimate_scales([yaw[run] for run in runs], cfg.smooth_order, cfg.smooth_floor_rad, cfg.noise_floor_rad)
    if xy is not None:
        out.update(prior_m=xy.noise, smooth_m=xy.motion)
    if turn is not None:
        out.update(prior_rad=turn.noise, smooth_rad=turn.motion)
    if cfg.slip_m > 0 and cfg.heading_chord_m > 0:
        off_path = heading_disagreement([centres[run, :2] for run in runs], [yaw[run] for run in runs],
                                        cfg.heading_chord_m)
        if off_path is not None:
            out["prior_rad"] = max(out["prior_rad"], off_path)
    return out


def _yaw_matrix(psi: torch.Tensor) -> torch.Tensor:
    c, s = torch.cos(psi), torch.sin(psi)
    z, o = torch.zeros_like(psi), torch.ones_like(psi)
    return torch.stack([torch.stack([c, -s, z]), torch.stack([s, c, z]), torch.stack([z, z, o])])


class PoseRefinement:
    """One tracked vehicle's per-frame corrections, their priors and their optimiser."""

    def __init__(self, actor_id: str, boxes: list[Pose | None], cuts: set[int], cfg: PoseRefineConfig,
                 start: int):
        self.actor_id, self.cfg, self.start = actor_id, cfg, start
        self.n_frames = len(boxes)
        self.frames = [f for f, p in enumerate(boxes) if p is not None]
        self.row = {f: i for i, f in enumerate(self.frames)}
        present = [boxes[f] for f in self.frames]
        self.base_R = torch.tensor(np.stack([p.R for p in present]), dtype=torch.float64)
        self.base_T = torch.tensor(np.stack([p.translation for p in present]), dtype=torch.float64)
        self.pieces = [[self.row[f] for f in run] for run in pieces(self.frames, cuts)]
        yaw = np.array([yaw_of(p.rotation) for p in present])
        for run in self.pieces:  # differences along a piece must not see a wrap at +-pi
            yaw[run] = np.unwrap(yaw[run])
        self.base_yaw = torch.tensor(yaw, dtype=torch.float64)
        self.scales = track_scales(self.base_T.numpy(), yaw, self.pieces, cfg)
        self.piece_rows = [torch.tensor(run) for run in self.pieces]  # made once: the priors run every step
        self.dt = torch.nn.Parameter(torch.zeros(len(present), 3, dtype=torch.float64))
        self.dyaw = torch.nn.Parameter(torch.zeros(len(present), dtype=torch.float64))
        self.opt = torch.optim.Adam([{"params": [self.dt], "lr": cfg.lr_m, "name": "dt"},
                                     {"params": [self.dyaw], "lr": cfg.lr_rad, "name": "dyaw"}])

    def pose(self, frame: int) -> tuple[torch.Tensor, torch.Tensor]:
        """(R [3, 3], T [3]) float64 at ``frame``, in the graph of the corrections."""
        r = self.row[frame]
        return _yaw_matrix(self.dyaw[r]) @ self.base_R[r], self.base_T[r] + self.dt[r]

    def penalty(self, n_views: int) -> torch.Tensor:
        """The priors of the corrections (towards the track, smooth in time), per training view."""
        c, s = self.cfg, self.scales
        prior = (self.dt.pow(2).sum() / s["prior_m"] ** 2 + self.dyaw.pow(2).sum() / s["prior_rad"] ** 2)
        T, yaw = self.base_T + self.dt, self.base_yaw + self.dyaw
        smooth = torch.zeros((), dtype=torch.float64)
        for idx in self.piece_rows:
            Ti, yi = T[idx], yaw[idx]
            if len(idx) > c.smooth_order:
                smooth = smooth + torch.diff(Ti, c.smooth_order, dim=0).pow(2).sum() / s["smooth_m"] ** 2
                smooth = smooth + torch.diff(yi, c.smooth_order).pow(2).sum() / s["smooth_rad"] ** 2
            if c.slip_m > 0 and len(idx) > 1:
                move, heading = torch.diff(Ti, dim=0), 0.5 * (yi[1:] + yi[:-1])
                sideways = move[:, 1] * torch.cos(heading) - move[:, 0] * torch.sin(heading)
                smooth = smooth + sideways.pow(2).sum() / c.slip_m ** 2
        return c.weight * (prior + smooth) / max(n_views, 1)

    def step(self, it: int) -> None:
        """Apply the step's gradient from iteration ``start`` on; clear it either way."""
        if it >= self.start:
            self.opt.step()
        self.opt.zero_grad(set_to_none=True)

    def refined(self) -> list[Pose | None]:
        """The refined pose of every frame (None where the track has no box)."""
        out: list[Pose | None] = [None] * self.n_frames
        with torch.no_grad():
            for f in self.frames:
                R, T = self.pose(f)
                out[f] = Pose(T.numpy().copy(), matrix_to_quat(R.numpy()))
        return out

    def corrections(self) -> dict:
        """Mean and largest correction (cm, degrees): what the fit moved the boxes by."""
        dt = self.dt.detach().norm(dim=1).numpy() * 100
        dyaw = np.degrees(np.abs(self.dyaw.detach().numpy()))
        return {"mean_cm": round(float(dt.mean()), 2), "max_cm": round(float(dt.max()), 2),
                "mean_deg": round(float(dyaw.mean()), 3), "max_deg": round(float(dyaw.max()), 3),
                "scales": {k: round(v, 5) for k, v in self.scales.items()}}

    # checkpoints: the corrections and their Adam state, so a resumed fit continues them

    def save(self, folder: Path) -> None:
        from safetensors.torch import save_file

        tensors = {"dt": self.dt.detach(), "dyaw": self.dyaw.detach()}
        for group in self.opt.param_groups:
            for key, v in self.opt.state.get(group["params"][0], {}).items():
                tensors[f"adam.{group['name']}.{key}"] = v.reshape(-1) if key == "step" else v
        folder.mkdir(parents=True, exist_ok=True)
        with atomic_path(folder / "poses.safetensors") as tmp:
            save_file({k: v.contiguous() for k, v in tensors.items()}, str(tmp))

    def load(self, folder: Path) -> None:
        from safetensors import safe_open

        path = folder / "poses.safetensors"
        if not path.exists():
            return
        with safe_open(str(path), "pt") as f, torch.no_grad():
            self.dt.copy_(f.get_tensor("dt"))
            self.dyaw.copy_(f.get_tensor("dyaw"))
            for group in self.opt.param_groups:
                name = group["name"]
                if f"adam.{name}.step" in f.keys():
                    self.opt.state[group["params"][0]] = {
                        "step": f.get_tensor(f"adam.{name}.step").reshape(()),
                        "exp_avg": f.get_tensor(f"adam.{name}.exp_avg"),
                        "exp_avg_sq": f.get_tensor(f"adam.{name}.exp_avg_sq")}


# ---------------------------------------------------------------- written back


def write_refined(out: Path, refined: dict[str, list[Pose | None]]) -> None:
    """``out/poses.json``: the refined poses of each refined vehicle, one per frame (null: no box)."""
    doc = {"actors": {k: [None if p is None else p.to_json() for p in v] for k, v in refined.items()}}
    write_text_atomic(Path(out) / POSES_FILE, json.dumps(doc, indent=1) + "\n")


def read_refined(folder: Path) -> dict[str, list[Pose | None]]:
    """The refined poses a reconstruction in ``folder`` wrote (none: an empty dict)."""
    path = Path(folder) / POSES_FILE
    if not path.exists():
        return {}
    doc = json.loads(path.read_text(encoding="utf-8"))
    return {k: [None if p is None else Pose(np.asarray(p["translation"], np.float64),
                                            np.asarray(p["rotation"], np.float64)) for p in v]
            for k, v in doc["actors"].items()}


def with_refined(manifest: Manifest, refined: dict[str, list[Pose | None]]) -> Manifest:
    """``manifest`` (changed in place, and returned) with each refined actor's recorded poses the
    refined ones and the tracks' boxes kept as ``tracked_poses``. An edit (``poses`` apart from
    the recorded poses at a frame) stays as it is; elsewhere ``poses`` follow the refinement, so
    renders, edits, the add-on and the simulator place the vehicle where its Gaussians were fitted."""
    for a in manifest.actors:
        if a.id not in refined:
            continue
        new = refined[a.id]
        edited = set(a.edited_frames())
        if a.tracked_poses is None:
            a.tracked_poses = [a.recorded_pose(f) for f in range(len(a.poses))]
        if a.recorded_poses is not None:
            a.recorded_poses = list(new)
        a.poses = [a.poses[f] if f in edited else new[f] for f in range(len(a.poses))]
    return manifest


def refinements(manifest: Manifest, tracks: list, cfg) -> tuple[list, dict[str, PoseRefinement]]:
    """(the recorded vehicles to fit, those refined placed at the tracks' boxes; a refinement per
    refined vehicle) for a fit of ``manifest`` with ``cfg`` (a ``ReconstructConfig``)."""
    chosen = refined_actors(manifest, cfg.pose_refine, [t.actor_id for t in tracks])
    start = round(cfg.pose_refine.start_fraction * cfg.iters)
    fitted, out = [], {}
    for t in tracks:
        if t.actor_id in chosen:
            t = replace(t, poses=track_boxes(manifest, t.actor_id))
            out[t.actor_id] = PoseRefinement(t.actor_id, t.poses, reported_frames(manifest, t.actor_id),
                                             cfg.pose_refine, start)
        fitted.append(t)
    return fitted, out
