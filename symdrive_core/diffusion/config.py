"""The diffusion stack's defaults, as config dataclasses that import no torch.

Callers compose them (``pipeline.stages.StageOptions``, the command line's ``--help``), so a
default is one edit and ``symdrive plan`` never loads torch. The code that uses each config
lives beside it: ``sampler.py``, ``train.py``, ``refine.py``, ``flux_train.py``, ``unet.py``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

GUIDE_CHANNELS = 4  # the warp (3) and its validity mask (1)
LORA_TARGETS = ("to_q", "to_k", "to_v", "to_out.0")
FLUX_PROMPT_TOKENS = 512  # T5 tokens of the prompt embedding, FLUX.1-dev's


@dataclass(frozen=True)
class UNetConfig:
    width: int = 24
    mults: tuple[int, ...] = (1, 2, 4, 4)
    image_channels: int = 3  # per view; the input holds three views
    groups: int = 8
    # "skip": the output is a correction on top of a precision-weighted blend of the noisy
    # state and the mean of the two conditions (see ``UNet.forward``); "v": the raw velocity.
    output: str = "skip"
    # prior spread of the centre view around the condition mean, [-1, 1] units. The measured
    # RMS error of the mean on the demo pairs is 0.18-0.30, but a smaller value keeps what the
    # network has not learned from turning into per-pixel sampling noise (the ODE reproduces
    # the prior spread exactly), so an undertrained model stays close to the mean.
    cond_sigma: float = 0.1
    data_sigma: float = 0.4  # RMS of images in [-1, 1] units (input scaling of z_t)
    # extra input channels after the three views: 4 for the geometry-guided warp of the target
    # camera and its validity mask (see ``with_guide``); 0 for the unguided network
    guide_channels: int = 0

    def to_json(self) -> dict:
        return {**asdict(self), "mults": list(self.mults)}

    @classmethod
    def from_json(cls, d: dict) -> UNetConfig:
        d = {"output": "v", **d}  # checkpoints written before "output" existed predict v
        return cls(**{**d, "mults": tuple(d["mults"])})


@dataclass(frozen=True)
class SamplerConfig:
    steps: int = 50
    n_start: int = 10  # the paper's position-accurate start (0 = from pure noise)
    seed: int = 0
    # Average of this many independent samples (one batch): an estimate of the posterior mean,
    # which is what PSNR rewards, at up to this many times the cost. 1 is the paper's single sample.
    samples: int = 1
    # Start from the initialisation without noise: one deterministic sample in place of the mean
    # of ``samples`` (``samples`` is then ignored). With the built-in restorer's one step from
    # t = 0.2 it scores as the mean of 8 does, for an eighth of the work (docs/results.md). A
    # sampler that starts from pure noise (``n_start`` 0) has no initialisation to start from and
    # draws its noise whatever this says.
    noise_free: bool = False
    # Share of the restorer's correction kept: the view is ``start + strength * (restored - start)``
    # (see :mod:`.strength`). None: the restorer's own, which an adaptation fits on the drive's
    # held-out recorded frames (1 for weights that record none: the full correction).
    strength: float | None = None
    # A guided restorer's view keeps the warp where the warp's mask is set: there the recorded
    # frames saw the ground, checked against depth. The restorer's correction fills the rest
    # (objects, what no frame saw); the mask's pixels still condition it. None: what the weights
    # record (an adaptation chooses it on held-out frames with lateral truth, :mod:`.strength`),
    # else True. On the built-in street the restorer's output lost 2 to 9 dB to the warp inside the
    # mask (docs/results.md).
    keep_warp: bool | None = None
    # Memory for one denoiser evaluation (GiB, None: no limit): beyond it the batch of samples is
    # split, then the image is cut into overlapping tiles (see :mod:`.tiling`).
    max_memory_gib: float | None = None
    tile: int = 256
    tile_overlap: int = 32

    def tiling(self):
        from .tiling import TileOptions

        return TileOptions(max_memory_gib=self.max_memory_gib, tile=self.tile, overlap=self.tile_overlap)


@dataclass
class TrainConfig:
    steps: int = 3000
    batch: int = 8
    crop: int = 64
    lr: float = 4e-4
    warmup: int = 100
    ema: float = 0.999
    seed: int = 0
    checkpoint_every: int = 250
    threads: int = 1  # 2+ threads on a shared 2-core machine ran 20x slower (oversubscription)
    width: int = UNetConfig.width
    mults: tuple[int, ...] = UNetConfig.mults
    output: str = UNetConfig.output  # "skip" (correction on the condition mean) or "v"
    # noise levels trained on: uniform on [0, t_max] plus a full_fraction share on [0, 1].
    # The default sampler (50 steps, N_start 10, no shift) starts at t = 0.8.
    t_max: float = 0.85
    full_fraction: float = 0.1
    # share of samples whose noisy state starts from a degraded render (pairs files with cycles)
    degraded_fraction: float = 0.5
    start_t_min: float = 0.1  # their lowest noise level (see flow.flow_loss)
    init: str | None = None  # restorer weights to start from (default: a fresh network)
    guide: bool = False  # the warp and its mask as a condition (pairs with warps)
    holdout_frames: tuple[int, ...] = ()  # recorded frames whose pairs training leaves out
    # stop after this many seconds of training even if fewer than ``steps`` ran (None: no limit);
    # the learning-rate schedule still spans ``steps``, and the EMA so far is what ships
    max_seconds: float | None = None

    def unet(self) -> UNetConfig:
        return UNetConfig(width=self.width, mults=tuple(self.mults), output=self.output,
                          guide_channels=GUIDE_CHANNELS if self.guide else 0)


@dataclass
class RefineConfig:
    iters: int = 900
    ssim_lambda: float = 0.2
    depth_weight: float = 0.1
    novel_weight: float = 1.0
    seed: int = 0


@dataclass
class FluxTrainConfig:
    steps: int = 20000  # the paper's
    batch: int = 1  # pairs per step and process
    crop: int = 512  # square crop in pixels (clipped to the image; trimmed to whole 2x2 latent patches)
    lr: float = 1e-4
    warmup: int = 100
    rank: int = 128  # the paper's
    alpha: float | None = None  # LoRA scale numerator (default: the rank, i.e. scale 1)
    targets: tuple[str, ...] = LORA_TARGETS
    seed: int = 0
    checkpoint_every: int = 500
    grad_accum: int = 1
    max_grad_norm: float = 1.0
    gradient_checkpointing: bool = True
    mixed_precision: str = "auto"  # "auto": bf16 on CUDA, none (float32) on the CPU; or "no" / "bf16" / "fp16"
    guidance: float = 3.5  # Flux.1-dev's distilled guidance input, as sampling uses it
    t_max: float = 1.0  # noise levels before the shift: uniform on [0, t_max]
    degraded_fraction: float = 0.5  # share started from a degraded render when the pairs have them
    start_t_min: float = 0.1
    # The same batch and noise at every step (an overfitting check, not for real training).
    fixed_batch: bool = False
    threads: int | None = None  # torch CPU threads (default: torch's)

    def lora_meta(self) -> dict:
        return {"rank": self.rank, "alpha": self.alpha or self.rank, "targets": list(self.targets)}


# The sampler per restorer backend. The built-in restorer's are measured (`symdrive bench
# accuracy-time`): its errors add up per step, so one step from t = 0.2; from a noise-free start
# that one step scores as the mean of 8 noisy samples does (which cancels their grain), for an
# eighth of the work. Flux keeps the paper's 50 steps from step 10, one sample.
SAMPLERS = {"builtin": SamplerConfig(steps=5, n_start=4, samples=8, noise_free=True), "flux": SamplerConfig()}


@dataclass(frozen=True)
class CycleConfig:
    """Budget of each cycle reconstruction (``make-pairs --cycle``): about 1.5 minutes each on the
    built-in street, shorter than a full reconstruction."""

    iters: int = 1000
    max_gaussians: int = 60000
