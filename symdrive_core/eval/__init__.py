"""Every claim measured against truth: the scorers, apart from what they score.

:mod:`.views` (held-out frames and lateral views of a reconstruction: PSNR, SSIM, lane IoU; the
one lateral scorer), :mod:`.restoration` (the restoration study: each method against the lateral
truth, and refinement next to its control), :mod:`.insertion` (inserted vehicles against the
truth of the vehicle in the scene), :mod:`.lane_paint` (lane markings and their truth). The image
metrics themselves are :mod:`symdrive_core.metrics`, which training losses use too.
"""
