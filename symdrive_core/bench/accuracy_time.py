"""What accuracy costs in time: every knob that trades one for the other, measured in one run.

Each knob setting is a callable that does the real work once and returns its quality against
ground truth; its wall time is measured around the call. The table, a JSON copy and a Pareto plot
(time vs PSNR) are written side by side, with the default setting of each knob marked. Lateral
settings also carry the colour-corrected ``psnr_cc`` (a column of the table); Pareto optimality
stays on plain PSNR, the one score every knob has.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from ..io.atomic import atomic_path, write_text_atomic


@dataclass
class Setting:
    knob: str
    value: str
    default: bool
    measure: Callable[[], dict]  # -> {"psnr", "ssim", optional "psnr_cc", "lane_iou", "per": "frame"}; real work


def run_settings(settings: list[Setting], progress: bool = True) -> list[dict]:
    from tqdm import tqdm

    rows = []
    for s in tqdm(settings, desc="accuracy-time", unit="setting", disable=not progress):
        t0 = time.perf_counter()
        quality = s.measure()
        elapsed = time.perf_counter() - t0
        seconds = quality.pop("seconds") if "seconds" in quality else elapsed
        rows.append({"knob": s.knob, "value": s.value, "default": s.default, "seconds": round(seconds, 4),
                     **{k: (round(v, 4) if isinstance(v, float) else v) for k, v in quality.items()}})
    for knob in {r["knob"] for r in rows}:
        mine = [r for r in rows if r["knob"] == knob]
        for r in mine:  # Pareto-optimal: no other setting is both faster and at least as accurate
            r["pareto"] = not any(o is not r and o["seconds"] <= r["seconds"] and o["psnr"] >= r["psnr"]
                                  and (o["seconds"] < r["seconds"] or o["psnr"] > r["psnr"]) for o in mine)
    return rows


def format_table(rows: list[dict]) -> str:
    lines = ["| knob | setting | PSNR (dB) | PSNR-cc (dB) | SSIM | lane IoU | seconds | per | Pareto |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        name = f"**{r['value']}** (default)" if r["default"] else r["value"]
        cc = f"{r['psnr_cc']:.2f}" if "psnr_cc" in r else ""
        lane = f"{r['lane_iou']:.1f}" if "lane_iou" in r else ""
        lines.append(f"| {r['knob']} | {name} | {r['psnr']:.2f} | {cc} | {r.get('ssim', float('nan')):.4f} | {lane} | "
                     f"{r['seconds']:.3f} | {r.get('per', 'run')} | {'yes' if r['pareto'] else ''} |")
    return "\n".join(lines)


def write_outputs(rows: list[dict], out_dir: str | Path, notes: dict[str, str] | None = None) -> dict[str, Path]:
    """accuracy_time.json, accuracy_time.md (table + why each default), pareto.png."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_text_atomic(out / "accuracy_time.json", json.dumps({"rows": rows, "defaults": notes or {}}, indent=1))
    md = ["# Accuracy vs time", "", format_table(rows), ""]
    for knob, why in (notes or {}).items():
        md.append(f"- **{knob}**: {why}")
    write_text_atomic(out / "accuracy_time.md", "\n".join(md) + "\n")
    knobs = list(dict.fromkeys(r["knob"] for r in rows))
    columns = min(4, len(knobs))
    rows_n = (len(knobs) + columns - 1) // columns
    fig, axes = plt.subplots(rows_n, columns, figsize=(3.6 * columns, 3.0 * rows_n), squeeze=False)
    for ax in axes.ravel()[len(knobs):]:
        ax.axis("off")
    for ax, knob in zip(axes.ravel(), knobs):
        mine = sorted((r for r in rows if r["knob"] == knob), key=lambda r: r["seconds"])
        ax.plot([r["seconds"] for r in mine], [r["psnr"] for r in mine], "o-", color="0.6")
        for r in mine:
            ax.plot(r["seconds"], r["psnr"], "*" if r["default"] else "o", ms=12 if r["default"] else 6,
                    color="tab:red" if r["default"] else ("tab:blue" if r["pareto"] else "0.5"))
            ax.annotate(r["value"], (r["seconds"], r["psnr"]), fontsize=7, xytext=(3, 3), textcoords="offset points")
        ax.set_title(knob, fontsize=9)
        ax.ticklabel_format(useOffset=False)
        ax.set_xlabel(f"seconds per {mine[0].get('per', 'run')}")
        ax.set_ylabel("PSNR (dB)")
        ax.grid(alpha=0.3)
    fig.tight_layout()
    with atomic_path(out / "pareto.png") as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)
    return {"json": out / "accuracy_time.json", "md": out / "accuracy_time.md", "png": out / "pareto.png"}
