"""The restorer network's inference on the CPU, option by option, side by side in one process.

    python scripts/bench_restorer_cpu.py                    # 1920x1080 frame, 2 threads, best of 3
    python scripts/bench_restorer_cpu.py --width 960 --height 540 --repeat 5

One evaluation of the shipped guided restorer (the pipeline's default: one noise-free step from
t = 0.2 on the warp-guided chain) on random-but-image-like inputs of the given size, run by:

* ``eager``: torch, float32, NCHW (what the toolkit runs);
* ``channels_last``: the same with NHWC memory layout (oneDNN's preferred convolution layout);
* ``bf16``: ``torch.autocast("cpu", torch.bfloat16)`` (AVX-512 BF16 or AMX where the CPU has it),
  and the same in channels-last layout;
* ``compile``: ``torch.compile`` (inductor; its compile time is reported apart and not timed);
* ``onnxruntime`` and ``openvino``: the network exported to ONNX at this input size and run by
  those runtimes' CPU providers, where they are installed (``pip install onnxruntime openvino
  onnx onnxscript``; neither is a dependency of the toolkit), OpenVINO in float32 and in bfloat16.

For each: the best of ``--repeat`` timed evaluations, the ratio to ``eager`` in the same run, and
the largest difference of the restored image from ``eager``'s in 8-bit levels (the one-step image
``x0 = z - t v`` in [0, 1], times 255). Options that fail to build are reported with the reason.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path


def inputs(width: int, height: int, guide_channels: int, seed: int = 0):
    """A smooth random image and its neighbours a few pixels apart (the chain's three views), the
    noise-free state at t = 0.2, and a warp with a half-valid mask: values in the ranges the
    network sees, so reduced precision is tried on realistic magnitudes."""
    import torch
    import torch.nn.functional as F

    g = torch.Generator().manual_seed(seed)
    base = F.interpolate(torch.rand(1, 3, height // 16 + 2, width // 16 + 2, generator=g), size=(height + 8, width + 8),
                         mode="bicubic", align_corners=False).clamp(0, 1)
    base = base + 0.05 * torch.randn(base.shape, generator=g)
    left, centre, right = (base[..., 4:4 + height, s:s + width] * 2 - 1 for s in (0, 4, 8))
    t = torch.full((1,), 0.2)
    z = 0.8 * centre
    extra = []
    if guide_channels:
        mask = (torch.arange(width) < width // 2).float().expand(1, 1, height, width)
        extra = [torch.cat([centre, mask * 2 - 1], dim=1)]
    return (z, t, left, right, *extra)


def one_step_image(z, t, v):
    """The restored image in [0, 1] from one Euler step to t = 0."""
    return ((z - t.reshape(-1, 1, 1, 1) * v) * 0.5 + 0.5).clamp(0, 1)


def timed(fn, repeat: int) -> tuple[float, object]:
    out = fn()  # warm-up (oneDNN primitive creation, allocator)
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def options(net, args_in, tmp: Path):
    """(name, build) pairs; ``build()`` returns a callable of no argument giving the velocity."""
    import torch

    def eager():
        return lambda: net(*args_in)

    def channels_last():
        net_cl = type(net)(net.config)
        net_cl.load_state_dict(net.state_dict())
        net_cl = net_cl.eval().to(memory_format=torch.channels_last)
        cl = [a.contiguous(memory_format=torch.channels_last) if a.ndim == 4 else a for a in args_in]
        return lambda: net_cl(*cl)

    def autocast(fn):
        def run():
            with torch.autocast("cpu", dtype=torch.bfloat16):
                return fn().float()
        return run

    def bf16():
        return autocast(eager())

    def bf16_channels_last():
        return autocast(channels_last())

    def compiled():
        c = torch.compile(net)
        t0 = time.perf_counter()
        c(*args_in)
        print(f"  (torch.compile: first call {time.perf_counter() - t0:.1f} s)", flush=True)
        return lambda: c(*args_in)

    def exported() -> Path:
        path = tmp / "restorer.onnx"
        if not path.exists():
            torch.onnx.export(net, tuple(args_in), str(path), dynamo=False, opset_version=17,
                              input_names=[f"in{i}" for i in range(len(args_in))], output_names=["v"])
        return path

    def onnxruntime():
        import onnxruntime as ort

        so = ort.SessionOptions()
        so.intra_op_num_threads = torch.get_num_threads()
        sess = ort.InferenceSession(str(exported()), so, providers=["CPUExecutionProvider"])
        feed = {f"in{i}": a.numpy() for i, a in enumerate(args_in)}
        return lambda: torch.from_numpy(sess.run(None, feed)[0])

    def openvino(precision: str):
        def build():
            import openvino as ov

            model = ov.Core().compile_model(str(exported()), "CPU", {
                "INFERENCE_NUM_THREADS": torch.get_num_threads(), "INFERENCE_PRECISION_HINT": precision})
            feed = [a.numpy() for a in args_in]
            return lambda: torch.from_numpy(model(feed)[0])
        return build

    return [("eager", eager), ("channels_last", channels_last), ("bf16", bf16),
            ("bf16_channels_last", bf16_channels_last), ("compile", compiled), ("onnxruntime", onnxruntime),
            ("openvino", openvino("f32")), ("openvino_bf16", openvino("bf16"))]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--width", type=int, default=1920)
    p.add_argument("--height", type=int, default=1080)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--only", help="comma-separated options (default: all)")
    p.add_argument("--json", type=Path, help="also write the results here")
    args = p.parse_args(argv)

    import torch

    from symdrive_core.diffusion.defaults import GUIDED_WEIGHTS
    from symdrive_core.diffusion.models import load_builtin

    torch.set_num_threads(args.threads)
    net = load_builtin(GUIDED_WEIGHTS).net.eval().requires_grad_(False)
    args_in = inputs(args.width, args.height, net.config.guide_channels)
    wanted = set(args.only.split(",")) if args.only else None
    rows, reference = [], None
    print(f"{args.width}x{args.height}, {args.threads} threads, best of {args.repeat}", flush=True)
    with torch.inference_mode(), tempfile.TemporaryDirectory() as tmp:
        for name, build in options(net, args_in, Path(tmp)):
            if wanted and name not in wanted and name != "eager":
                continue
            try:
                seconds, v = timed(build(), args.repeat)
            except Exception as exc:  # an optional runtime missing or failing is a result, not a crash
                rows.append({"option": name, "error": f"{type(exc).__name__}: {exc}".splitlines()[0][:200]})
                print(f"  {name:<14} not run: {rows[-1]['error']}", flush=True)
                continue
            image = one_step_image(args_in[0], args_in[1], v.float())
            reference = image if reference is None else reference
            row = {"option": name, "seconds": round(seconds, 3),
                   "speedup": round(rows[0]["seconds"] / seconds, 2) if rows else 1.0,
                   "max_diff_levels": round(float((image - reference).abs().max()) * 255, 3),
                   "mean_diff_levels": round(float((image - reference).abs().mean()) * 255, 4)}
            rows.append(row)
            print(f"  {name:<14} {seconds:7.3f} s  {row['speedup']:5.2f}x  max diff {row['max_diff_levels']:.3f} "
                  f"levels (mean {row['mean_diff_levels']:.4f})", flush=True)
    if args.json:
        args.json.write_text(json.dumps({"width": args.width, "height": args.height, "threads": args.threads,
                                         "torch": torch.__version__, "rows": rows}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
