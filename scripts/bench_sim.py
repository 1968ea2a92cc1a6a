"""Closed-loop simulation speed: steps per second on the demo street at two render sizes with
0, 5 and 25 SUMO vehicles, and the share of each step spent rendering, in SUMO and in the agent.

    python scripts/bench_sim.py [--steps 20] [--agent idm] [--device cpu]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from symdrive_core.sim import SimConfig, SymDriveEnv
from symdrive_core.sim.agents import load_agent

DEMO = Path(__file__).resolve().parents[1] / "symdrive_core" / "data" / "demo_street"


def bench(size, vehicles, steps, agent_name, device):
    cfg = SimConfig(image_size=size, traffic="sumo", sumo_vehicles=vehicles, time_limit_s=1e6,
                    route_end_margin_m=-1e6, offroad_margin_m=1e6, device=device)
    env = SymDriveEnv(DEMO, cfg)
    agent = load_agent(agent_name)()
    try:
        obs, _ = env.reset(seed=0)
        agent.reset(env, 0)
        env.render_camera(env.cameras[0].name)  # compile and warm the rasterizer
        env.timing = {k: 0.0 for k in env.timing}
        t_agent, n = 0.0, 0
        t0 = time.perf_counter()
        while n < steps and env.end_reason is None:
            t = time.perf_counter()
            action = agent.act(obs)
            t_agent += time.perf_counter() - t
            obs, *_ = env.step(action)
            n += 1
        wall = time.perf_counter() - t0
        seen = len(env.actors)
    finally:
        env.close()
    return n / wall, env.timing["render"] / wall, env.timing["traffic"] / wall, t_agent / wall, seen


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--agent", default="idm")
    ap.add_argument("--device", default="cpu")
    a = ap.parse_args()
    print(f"{'size':>8} {'vehicles':>8} {'in SUMO':>7} {'steps/s':>8} {'render':>7} {'SUMO':>6} {'agent':>6}")
    for size in [(256, 144), (640, 360)]:
        for vehicles in [0, 5, 25]:
            sps, r, s, g, seen = bench(size, vehicles, a.steps, a.agent, a.device)
            print(f"{size[0]}x{size[1]:<4} {vehicles:>8} {seen:>7} {sps:>8.2f} {r:>7.1%} {s:>6.1%} {g:>6.1%}",
                  flush=True)


if __name__ == "__main__":
    main()
