"""Run an agent for N episodes; score each; write report.json and one video per episode.

Every episode is independent: an agent that raises (in its constructor, ``reset`` or ``act``)
ends that episode with reason ``agent_error`` and the message, and the next episode runs.
Outputs go inside ``out`` only, each written atomically.
"""

from __future__ import annotations

import json
import time
import traceback
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..io.atomic import write_text_atomic
from ..pipeline.outputs import output_folder
from . import episode as ep
from .config import SimConfig
from .scores import score_episode


def run_episode(env, agent_cls, seed: int, *, video: str | Path | None = None, frames_out: list | None = None,
                inset: int | None = None) -> dict:
    """One episode of ``agent_cls`` in ``env`` from ``seed``: its record (scores included)."""
    from .video import birds_eye, compose, write_video

    obs, info = env.reset(seed=seed)
    frames = []
    cam = env.cameras[0].name

    def grab(o):
        if video is None and frames_out is None:
            return
        image = o.get("images", {}).get(cam)
        if inset:
            size = inset
        elif image is None:
            size = 256
        else:
            size = max(4, min(int(0.45 * image.shape[0]), image.shape[0] - 4, image.shape[1] - 4))
        frames.append(compose(image, birds_eye(env, env.history[-1], size)))

    grab(obs)
    agent_time = 0.0
    error = None
    try:
        t0 = time.perf_counter()
        agent = agent_cls()
        agent.reset(env, seed)
        agent_time += time.perf_counter() - t0
    except Exception as exc:  # the agent's own failure ends only this episode
        error = exc
        env.end(ep.AGENT_ERROR, f"{type(exc).__name__}: {exc}")
    while env.end_reason is None:
        try:
            t0 = time.perf_counter()
            action = agent.act(obs)
            agent_time += time.perf_counter() - t0
        except Exception as exc:
            error = exc
            env.end(ep.AGENT_ERROR, f"{type(exc).__name__}: {exc}")
            break
        obs, _, term, trunc, info = env.step(action)
        if env.end_reason != ep.INVALID_ACTION:
            grab(obs)
    scores = score_episode(env.history, env.dt, env.route.length - env.config.route_end_margin_m, env.end_reason)
    record = {"seed": seed, "steps": env.steps, "seconds": round(env.steps * env.dt, 6),
              "end_reason": env.end_reason, "end_detail": env.end_detail, "scores": scores,
              "timing_s": {**{k: round(v, 4) for k, v in env.timing.items()}, "agent": round(agent_time, 4)}}
    if error is not None:
        record["traceback"] = "".join(traceback.format_exception(error))[-4000:]
    if video is not None and frames:
        write_video(frames, video, 1.0 / env.dt)
        record["video"] = Path(video).name
    if frames_out is not None:
        frames_out.extend(frames)
    return record


def summarize(episodes: list[dict]) -> dict:
    keys = ["pdm_score", "no_collision", "drivable_area_compliance", "ttc", "comfort", "route_completion"]
    out = {k: float(np.mean([e["scores"][k] for e in episodes])) for k in keys} if episodes else {}
    reasons: dict[str, int] = {}
    for e in episodes:
        reasons[e["end_reason"]] = reasons.get(e["end_reason"], 0) + 1
    out["end_reasons"] = reasons
    return out


def run(package, agent: str, episodes: int, seed: int, out: str | Path, config: SimConfig | None = None, *,
        video: bool = True, allow_external_assets: bool = False, invocation: str | None = None,
        progress: bool = True) -> dict:
    """``symdrive sim``: every episode, then ``out/report.json``; returns the report."""
    from tqdm import tqdm

    from .agents import load_agent
    from .env import SymDriveEnv

    out = output_folder(out)
    config = config or SimConfig()
    agent_cls = load_agent(agent)
    env = SymDriveEnv(package, config, allow_external_assets=allow_external_assets)  # the package checked first
    out.mkdir(parents=True, exist_ok=True)
    records = []
    try:
        for i in tqdm(range(episodes), desc="sim", unit="episode", disable=not progress):
            path = out / f"episode_{i:03d}.mp4" if video else None
            rec = run_episode(env, agent_cls, seed + i, video=path)
            records.append({"episode": i, **rec})
    finally:
        env.close()
    report = {"package": str(env.manifest.path or env.manifest.root), "agent": agent, "episodes": records,
              "summary": summarize(records), "seed": seed, "dt": env.dt, "route_length_m": env.route.length,
              "drivable_area": env.area.summary(),
              "config": replace(config).to_json(), "invocation": invocation}
    write_text_atomic(out / "report.json", json.dumps(report, indent=1, default=float) + "\n")
    return report
