"""The compositing rules every renderer here shares (numba kernels, torch reference, float64 oracle,
projection, shadows, insertion): change a value here and every one of them follows.

The values are 3DGS's own: a Gaussian whose alpha would not show in an 8-bit image is skipped,
alpha is clamped below 1 so transmittance never reaches 0 (its gradient stays finite), and a pixel
stops compositing once almost no light is left.
"""

ALPHA_THRESHOLD = 1.0 / 255.0  # contributions below this are skipped
ALPHA_MAX = 0.99  # alpha clamp
T_STOP = 1e-4  # a pixel stops when its transmittance would fall to this or below
EXTENT_CAP = 3.33  # screen extent of a Gaussian in sigmas at the default threshold (gsplat's rule)
TILE_SIZE = 16  # pixels per tile side
EPS2D = 0.3  # added to the 2D covariance's diagonal (pixels^2): the low-pass of 3DGS and gsplat
FOV_CLAMP_MARGIN = 0.3  # camera-space means clamped to (1 + this) x the half field of view for the Jacobian (3DGS)
