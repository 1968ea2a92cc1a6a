"""Defaults of reconstruction, density control and the inserted vehicles' fine-tune, as config
dataclasses that import no torch, so the pipeline's options and the command line compose them
without loading the optimisers (``reconstruct.py``, ``densify.py``, ``finetune.py``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

COARSE_TO_FINE = (0.1, 0.3)  # 1/4 resolution until 10 % of the iterations, 1/2 until 30 %, full after


@dataclass
class DensifyConfig:
    grad_threshold: float = 0.0002  # mean NDC gradient norm above which a Gaussian densifies
    dense_fraction: float = 0.01  # clone below this size (fraction of the scene extent), split above
    min_opacity: float = 0.005
    max_angular_size: float = 0.25  # prune when the largest axis exceeds this fraction of its distance
    max_gaussians: int = 200_000


@dataclass
class PoseRefineConfig:
    """Per-frame pose corrections of tracked vehicles, fitted with their Gaussians (``pose_refine.py``)."""

    # None: the vehicles whose boxes came from tracks (``source.tracks``, as ``import tracks`` records
    # them); True: every recorded vehicle; False: none (the boxes taken as exact).
    enabled: bool | None = None
    start_fraction: float = 0.1  # corrections wait until then: a vehicle's Gaussians start as a grey box
    # Adam's step of the translation corrections, metres per iteration (2e-3 against 1e-3: nearer the
    # truth on jittered boxes at every seed measured, docs/results.md)
    lr_m: float = 2e-3
    lr_rad: float = 2e-4  # and of the yaw corrections, radians
    prior_m: float = 0.3  # the track's error scale the pull towards it assumes
    prior_rad: float = 0.05
    smooth_order: int = 2  # the difference smoothed: 2 acceleration, 3 jerk (a steady turn or lane change costs nothing)
    smooth_m: float = 0.05  # a difference of the trajectory this large costs as a prior_m correction
    smooth_rad: float = 0.01
    # The four scales above estimated from each track itself (:mod:`.track_noise`): a tracker's error
    # and a car's changes of motion differ by track; the configured ones stay where a track is too
    # short to tell them apart. False: the configured ones for every track.
    scales_from_track: bool = True
    # The estimated scales are at least these. A box's error that changes smoothly (labels set at key
    # frames, a few centimetres off where the images have the car) leaves no differences to see;
    # 3 cm against 1 cm lifted a real drive's driving car at three seeds of three (docs/results.md)
    noise_floor_m: float = 0.03
    noise_floor_rad: float = 0.002
    smooth_floor_m: float = 0.005
    smooth_floor_rad: float = 0.001
    # A car moves where it points: the sideways part of its move between consecutive frames, at
    # the pair's mean heading, costs as a prior_m correction at this size (metres; 0: off). It ties
    # each box's heading to its path, so neither is smoothed alone.
    slip_m: float = 0.02
    # With the slip, a moving track's heading error is at least how far its boxes' headings turn
    # from its path: the angle to the chord of at least this length centred on each box (metres;
    # 0: off). A heading set by hand can be degrees off yet smooth, which its differences miss.
    heading_chord_m: float = 4.0
    weight: float = 1e-3  # of the priors against one view's photometric loss


@dataclass
class CameraRefineConfig:
    """Per-frame corrections of the recorded camera poses, fitted with the Gaussians (``camera_refine.py``)."""

    # Off: on a real drive it raised a static fit's held-out PSNR by 0.44 dB but lowered the
    # decomposed default's by 0.23, and on exact poses it cost 0.82 (docs/results.md).
    enabled: bool = False
    start_fraction: float = 0.1  # corrections wait until then, once the Gaussians look like the street
    lr_rad: float = 2e-4  # Adam's step of the rotation vectors, radians per iteration
    lr_m: float = 2e-3  # and of the translations, metres
    prior_rad: float = 0.01  # the pull towards the recorded poses assumes errors of this size
    prior_m: float = 0.2
    weight: float = 1e-3  # of the pull against one view's photometric loss


@dataclass
class SkyConfig:
    """Where the sky dome starts in a view without depth (:mod:`.sky`)."""

    # Without depth, the sky estimated above the horizon and the point cloud's skyline; off: no
    # dome where no depth marks the sky (sparse sensor depth: ``sensor_dome_deg``).
    skyline: bool = True
    min_elevation_deg: float = 1.0  # a sky ray is at least this far above the horizon
    cell_px: int = 8  # the skyline's resolution in pixels, both ways
    neighbour_cells: int = 1  # a column's skyline is the highest over this many columns each side
    margin_cells: int = 0  # the sky starts this many cells above the skyline
    # Sparse sensor depth (a LiDAR's) marks no sky and its returns stop at the scanner's top beam, so
    # there the dome starts above the horizon and the returns' skyline, as broad Gaussians (one
    # standard deviation this many degrees, seen from the dome's centre) that keep their places and
    # sizes and never densify: a part of the fit of its own, written into the background at the end.
    # They draw the sky's smooth colours but not the upper storeys the scanner missed, which the
    # street's Gaussians must grow to draw. 0: no dome where the depth is a sensor's.
    sensor_dome_deg: float = 5.0


@dataclass
class ReconstructConfig:
    iters: int = 3000
    # Coarse to fine: fractions of ``iters`` at each of which the training images' downscale
    # halves, e.g. (0.1, 0.3): 4x until 10 %, 2x until 30 %, full resolution after; () = full
    # resolution throughout. Early iterations place and colour Gaussians, which needs no fine detail.
    # None: COARSE_TO_FINE for images of at least ``coarse_to_fine_pixels`` pixels, else full
    # resolution (measured at 3000 iterations: ahead on two real drives of 113k and 117k pixels,
    # behind on a 37k-pixel Cycles street; docs/results.md).
    resolution_schedule: tuple[float, ...] | None = None
    coarse_to_fine_pixels: int = 100_000
    sh_degree: int = 1
    sh_every: int = 1000  # raise the active SH degree every this many iterations
    lr_means: float = 1.6e-4  # times the scene extent; decays exponentially to lr_means_final
    lr_means_final: float = 1.6e-6
    lr_sh0: float = 2.5e-3
    lr_shN: float = 2.5e-3 / 20
    lr_opacity: float = 5e-2
    lr_scales: float = 5e-3
    lr_quats: float = 1e-3
    ssim_lambda: float = 0.2
    # Inverse-depth L1 at the depth maps' measured pixels, this weight (0 = off); None: the
    # ``sensor_depth_weight`` where the camera's depth is a sensor's sparse measurement
    # (``depth_zero: "unmeasured"``, as ``import lidar`` writes it), off for other depth maps.
    depth_weight: float | None = None
    sensor_depth_weight: float = 1.0  # the largest measured weight that kept held-out PSNR (docs/results.md)
    init_opacity: float = 0.3
    sky_points: int = 4000  # the sky dome's Gaussians at the start
    sky: SkyConfig = field(default_factory=SkyConfig)
    max_init_points: int = 30000  # random subset of the point cloud (CPU time grows with the count)
    densify_from: int = 300
    densify_until_fraction: float = 0.6
    densify_every: int = 100
    densify: DensifyConfig = field(default_factory=DensifyConfig)
    # When density control ends, this fraction of each part's Gaussians, those that paint the least
    # of the training views (their blending weights summed, :mod:`.importance`), is removed: every
    # later step composites fewer. 0: none.
    importance_prune: float = 0.0
    holdout_every: int = 5  # used when the package does not name its held-out frames
    checkpoint_every: int = 500
    seed: int = 0
    # Recorded vehicles (existing actors with a box) fitted in their own frames; off: one static scene.
    decompose: bool = True
    actor_points: int = 3000  # initial Gaussians per recorded vehicle: its measured surface, then its box's faces
    actor_max_gaussians: int = 40_000
    # Each pixel a recorded vehicle covers costs this much (its accumulated alpha, against the
    # photometric loss of that pixel): a vehicle keeps only what draws better than the background
    # behind it, so the slack of a loose box does not take up the street seen past the car. 0 (off,
    # the default): on a real tracked drive 0.01 evened out the seeds without a mean gain beyond
    # their spread, and on the Cycles traffic street it cost the removals 1.7 dB (docs/results.md).
    vehicle_alpha_weight: float = 0.0
    # Views that show a recorded vehicle driving (its box's centre moves more than ``driving_m`` over
    # the drive) come this many times in each pass over the views: its Gaussians learn from those
    # views only. 1 (off, the default): 2 lifted a real drive's driving car by 0.97 dB on average
    # over four seeds but cost its whole held-out drive 0.23 dB (the other frames' share of the
    # iterations fell), and a static fit given the same frames twice gained 0.8 dB there too
    # (docs/results.md).
    driving_view_repeat: int = 1
    driving_m: float = 2.0
    pose_refine: PoseRefineConfig = field(default_factory=PoseRefineConfig)
    camera_refine: CameraRefineConfig = field(default_factory=CameraRefineConfig)
    # Where the scene has a sun, each recorded vehicle's shadow is a layer fitted with the
    # Gaussians (:mod:`.recorded_shadows`), at this learning rate on its occlusion logits.
    shadow_lr: float = 0.05
    # Each view's render through a learnt affine colour transform before the loss
    # (:mod:`.exposure`): "camera" (one per camera but the first, which the scene's colours are
    # in), "frame" (one per view, pulled towards the identity) or "off".
    exposure: str = "camera"
    lr_exposure: float = 1e-3

    @property
    def densify_end(self) -> int:
        """The step at which density control stops (and the least important Gaussians go)."""
        return int(self.densify_until_fraction * self.iters)

    def schedule_for(self, pixels: int) -> tuple[float, ...]:
        """The resolution schedule a fit of images of ``pixels`` pixels (the largest) trains with."""
        if self.resolution_schedule is not None:
            return self.resolution_schedule
        return COARSE_TO_FINE if pixels >= self.coarse_to_fine_pixels else ()

    def downscale_at(self, it: int) -> int:
        """The factor the training images are downscaled by at iteration ``it`` (a power of 2),
        once the schedule is set (:meth:`schedule_for`; the training loop sets it)."""
        if self.resolution_schedule is None:
            raise ValueError("downscale_at: the resolution schedule depends on the images; set it with schedule_for")
        return 2 ** sum(it < round(f * self.iters) for f in self.resolution_schedule)

    def sh_degree_at(self, it: int) -> int:
        """The SH degree trained at iteration ``it``: one more every ``sh_every``, up to ``sh_degree``."""
        return min(self.sh_degree, it // self.sh_every)

    def depth_weight_for(self, camera) -> float:
        """The depth loss's weight for training on ``camera`` (a scene camera)."""
        if self.depth_weight is not None:
            return self.depth_weight
        return self.sensor_depth_weight if camera.depth_zero == "unmeasured" else 0.0


@dataclass
class FinetuneConfig:
    steps: int = 300
    lr_sh0: float = 5e-3  # DC term
    lr_shN: float = 5e-3 / 20  # higher-order terms, as 3DGS does
    lr_opacity: float = 2.5e-2
    ssim_lambda: float = 0.2
    seed: int = 0
