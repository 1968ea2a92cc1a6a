"""A family of generated streets for the restorer: each street varies what another drive varies,
is reconstructed as the built-in street is, and gives restorer training pairs.

    python scripts/street_family.py --out out/family --streets 8 [--first-seed 100] [--only-settings]
    python scripts/street_family.py --out out/measure --streets 2 --first-seed 200 --measured

Street k takes seed ``first_seed + k``: its layout, and from it (:func:`street_settings`) the light
(a third overcast), the camera (height 1.4-2.0 m, pitch 1-6 degrees, a 18-32 mm lens on 36 mm, one
of three image sizes), the ground's materials (colours scaled by up to +/-25 % per channel) and
the sensor (noise up to 0.02, blur up to 1 pixel, exposure up to +/-15 % a frame). Each street
goes through three steps, each skipped when its output exists, so a stopped run continues where
it stopped:

1. ``street/``: ``scripts/make_world.py`` with 30 training frames and nothing else (no held-out
   frames, lateral truth or insertions: the pairs need only the recorded frames);
2. ``reconstruction/``: ``symdrive reconstruct`` with the defaults (converged, as the demo street's);
3. ``pairs.safetensors``: ``symdrive make-pairs`` from that reconstruction, the offsets and six
   cycle reconstructions of ``scripts/train_restorer.sh`` and the warps (one file serves both
   restorers).

``--measured`` makes streets to measure on instead: held-out frames and the lateral truth as the
built-in street has them, steps 1 and 2 only; give them seeds the training family does not use.

The built-in street joins the family (``demo_street/pairs.safetensors``: step 3 from its shipped
reconstruction). ``settings.json`` in each street's folder records what it drew; ``family.json``
lists the streets and their pairs files (``scripts/train_restorer_family.sh`` trains on them).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SYMDRIVE = [sys.executable, "-m", "symdrive_core.cli"]
DEMO = ROOT / "symdrive_core" / "data" / "demo_street"
SIZES = ((256, 144), (320, 176), (288, 128))  # width, height: the built-in street's and two others
OFFSETS = "0.5,1,1.5,2,2.5,3"
CYCLE = "-3,-2,-1,1,2,3"
SETTINGS_STREAM = 43  # the settings draw from (seed, this): a stream apart from the layout's, which is the seed's


def street_settings(seed: int) -> dict:
    """What street ``seed`` varies, drawn from the seed alone (the same seed, the same street)."""
    rng = np.random.default_rng([seed, SETTINGS_STREAM])
    width, height = SIZES[int(rng.integers(len(SIZES)))]
    return {
        "seed": seed, "overcast": bool(rng.random() < 1 / 3),
        "camera_height": round(float(rng.uniform(1.4, 2.0)), 3), "pitch": round(float(rng.uniform(1.0, 6.0)), 2),
        "lens_mm": round(float(rng.uniform(18.0, 32.0)), 1), "width": width, "height": height,
        "material_jitter": round(float(rng.uniform(0.0, 0.25)), 3), "noise": round(float(rng.uniform(0.0, 0.02)), 4),
        "blur": round(float(rng.uniform(0.0, 1.0)), 2), "exposure_jitter": round(float(rng.uniform(0.0, 0.15)), 3),
    }


def world_args(s: dict, out: Path, measured: bool = False) -> list[str]:
    """``make_world.py``'s arguments for settings ``s``: the training drive only, or with
    ``measured`` also held-out frames and the lateral truth (the built-in street's defaults)."""
    args = ["--out", str(out), "--seed", str(s["seed"]), "--frames", "30", "--placements", "0",
            "--width", str(s["width"]), "--height", str(s["height"])]
    if not measured:
        args += ["--holdout-every", "0", "--offsets"]
    for key in ("camera_height", "pitch", "lens_mm", "material_jitter", "noise", "blur", "exposure_jitter"):
        args += ["--" + key.replace("_", "-"), str(s[key])]
    return args + (["--overcast"] if s["overcast"] else [])


def run(label: str, cmd: list[str], log: Path) -> None:
    """Run ``cmd``, its output to ``log``; a failure stops the family, naming the log."""
    t0 = time.time()
    with open(log, "w") as f:
        done = subprocess.run(cmd, stdout=f, stderr=subprocess.STDOUT, cwd=ROOT)
    if done.returncode:
        sys.exit(f"{label} failed (exit {done.returncode}): see {log}")
    print(f"  {label}: {time.time() - t0:.0f} s", flush=True)


def make_pairs(package: Path, gaussians: Path | None, pairs: Path, log: Path) -> None:
    """Step 3: the pairs of ``package``'s training frames from ``gaussians`` (None: its own splats)."""
    if not pairs.exists():
        pairs.parent.mkdir(parents=True, exist_ok=True)
        splats = [] if gaussians is None else ["--gaussians", str(gaussians)]
        run("pairs", [*SYMDRIVE, "make-pairs", str(package), *splats, "--offsets", OFFSETS, f"--cycle={CYCLE}",
                      "--warps", "--out", str(pairs), "--quiet"], log)


def make_street(folder: Path, s: dict, measured: bool = False) -> Path:
    """Steps 1-3 for one street (each skipped when done); returns its pairs file. ``measured``:
    a street kept out of training, with held-out frames and lateral truth, and no pairs."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "settings.json").write_text(json.dumps(s, indent=1) + "\n")
    street, recon, pairs = folder / "street", folder / "reconstruction", folder / "pairs.safetensors"
    if not (street / "manifest.json").exists():
        run("street", [sys.executable, str(ROOT / "scripts" / "make_world.py"), *world_args(s, street, measured)],
            folder / "world.log")
    if not (recon / "metrics.json").exists():
        run("reconstruction", [*SYMDRIVE, "reconstruct", str(street), "--out", str(recon), "--resume", "--quiet"],
            folder / "reconstruct.log")
    if not measured:
        make_pairs(street, recon / "background.ply", pairs, folder / "pairs.log")
    return pairs


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="folder of the family (one sub-folder per street)")
    ap.add_argument("--streets", type=int, default=8)
    ap.add_argument("--first-seed", type=int, default=100)
    ap.add_argument("--only-settings", action="store_true", help="print each street's settings and stop")
    ap.add_argument("--measured", action="store_true",
                    help="streets to measure on, kept out of training: with held-out frames and lateral truth, "
                         "reconstructed, no pairs (use seeds the training family does not)")
    args = ap.parse_args()
    out = args.out.resolve()  # the steps run from the repository's root
    seeds = range(args.first_seed, args.first_seed + args.streets)
    if args.only_settings:
        for seed in seeds:
            print(json.dumps(street_settings(seed)))
        return 0
    done = []
    for k, seed in enumerate(seeds):
        s = street_settings(seed)
        print(f"street {k + 1}/{args.streets} (seed {seed}): {s}", flush=True)
        done.append({"seed": seed, "pairs": str(make_street(out / f"street_{seed}", s, args.measured))})
    if args.measured:
        return 0
    print("built-in street", flush=True)
    make_pairs(DEMO, None, out / "demo_street" / "pairs.safetensors", out / "demo_street.log")
    done.append({"seed": None, "pairs": str(out / "demo_street" / "pairs.safetensors")})
    (out / "family.json").write_text(json.dumps({"streets": done}, indent=1) + "\n")
    print("wrote", out / "family.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
