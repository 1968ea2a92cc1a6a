"""Per-Gaussian CPU kernels (numba): EWA projection and SH colour, forward and hand-written backward.

These are scalar transcriptions of the vectorised torch code in :mod:`.projection` and :mod:`.sh`
(the reference, differentiable by autograd): same masks, same clamps, same constants, float64
arithmetic throughout. The backward kernels recompute the forward quantities of one Gaussian and
apply the chain rule in reverse, reproducing autograd's conventions at the non-smooth points
(``clamp`` passes the gradient on its closed interval, ``torch.where`` masks it). One Gaussian per
``prange`` iteration; no shared writes.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .compile_notice import announce_compiles

announce_compiles()

# SH constants (the 3DGS basis; kept equal to .sh)
C0 = 0.28209479177387814
C1 = 0.4886025119029199
C2_0 = 1.0925484305920792
C2_1 = -1.0925484305920792
C2_2 = 0.31539156525252005
C2_3 = -1.0925484305920792
C2_4 = 0.5462742152960396
C3_0 = -0.5900435899266435
C3_1 = 2.890611442640554
C3_2 = -0.4570457994644658
C3_3 = 0.3731763325901154
C3_4 = -0.4570457994644658
C3_5 = 1.445305721320277
C3_6 = -0.5900435899266435

EXTENT_NUMBER = 0
EXTENT_OPACITY = 1


@njit(cache=True, inline="always")
def _isfinite(v):
    return not (math.isinf(v) or math.isnan(v))


@njit(cache=True, inline="always")
def _unit_quat(quats, i):
    """normalize_quats: (w, x, y, z, inv_norm, differentiable)."""
    w = float(quats[i, 0])
    x = float(quats[i, 1])
    y = float(quats[i, 2])
    z = float(quats[i, 3])
    if not (_isfinite(w) and _isfinite(x) and _isfinite(y) and _isfinite(z)):
        return 1.0, 0.0, 0.0, 0.0, 1.0, False
    n2 = w * w + x * x + y * y + z * z
    if not n2 > 1e-30:
        return 1.0, 0.0, 0.0, 0.0, 1.0, False
    inv = 1.0 / math.sqrt(n2)
    return w * inv, x * inv, y * inv, z * inv, inv, True


@njit(cache=True, inline="always")
def _rotmat(w, x, y, z, Rq):
    Rq[0, 0] = 1.0 - 2.0 * (y * y + z * z)
    Rq[0, 1] = 2.0 * (x * y - w * z)
    Rq[0, 2] = 2.0 * (x * z + w * y)
    Rq[1, 0] = 2.0 * (x * y + w * z)
    Rq[1, 1] = 1.0 - 2.0 * (x * x + z * z)
    Rq[1, 2] = 2.0 * (y * z - w * x)
    Rq[2, 0] = 2.0 * (x * z - w * y)
    Rq[2, 1] = 2.0 * (y * z + w * x)
    Rq[2, 2] = 1.0 - 2.0 * (x * x + y * y)


@njit(cache=True, inline="always")
def _gaussian_ok(means, quats, scales, opac, finite_mask, i):
    ok = finite_mask[i] and _isfinite(opac[i])
    for a in range(3):
        ok = ok and _isfinite(means[i, a]) and _isfinite(scales[i, a])
    for a in range(4):
        ok = ok and _isfinite(quats[i, a])
    return ok


@njit(cache=True, inline="always")
def _cov2d(i, ok, means, quats, scales, R, cam, fx, fy, lxn, lxp, lyn, lyp, near, far, rel, Rq, M, W, A):
    """Forward up to the 2D covariance. Fills rel (3,), Rq, M = Rq diag(s), W = J R, A = W M."""
    for a in range(3):
        rel[a] = (float(means[i, a]) if ok else 0.0) - cam[a]
    px = R[0, 0] * rel[0] + R[0, 1] * rel[1] + R[0, 2] * rel[2]
    py = R[1, 0] * rel[0] + R[1, 1] * rel[1] + R[1, 2] * rel[2]
    pz = R[2, 0] * rel[0] + R[2, 1] * rel[1] + R[2, 2] * rel[2]
    in_depth = ok and pz >= near and pz <= far
    zs = pz if in_depth else 1.0
    xs = px if in_depth else 0.0
    ys = py if in_depth else 0.0
    rz = 1.0 / zs
    ux = xs * rz
    uy = ys * rz
    tx = zs * min(max(ux, -lxn), lxp)
    ty = zs * min(max(uy, -lyn), lyp)
    rz2 = rz * rz
    J00 = fx * rz
    J02 = -fx * tx * rz2
    J11 = fy * rz
    J12 = -fy * ty * rz2
    for k in range(3):
        W[0, k] = J00 * R[0, k] + J02 * R[2, k]
        W[1, k] = J11 * R[1, k] + J12 * R[2, k]
    qw, qx, qy, qz, qinv, qgood = _unit_quat(quats, i)
    _rotmat(qw, qx, qy, qz, Rq)
    for b in range(3):
        s = float(scales[i, b]) if ok else 0.0
        for k in range(3):
            M[k, b] = Rq[k, b] * s
    for a in range(2):
        for b in range(3):
            A[a, b] = W[a, 0] * M[0, b] + W[a, 1] * M[1, b] + W[a, 2] * M[2, b]
    c00 = A[0, 0] * A[0, 0] + A[0, 1] * A[0, 1] + A[0, 2] * A[0, 2]
    c01 = A[0, 0] * A[1, 0] + A[0, 1] * A[1, 1] + A[0, 2] * A[1, 2]
    c11 = A[1, 0] * A[1, 0] + A[1, 1] * A[1, 1] + A[1, 2] * A[1, 2]
    return (in_depth, xs, ys, zs, rz, ux, uy, tx, ty, c00, c01, c11, qw, qx, qy, qz, qinv, qgood)


@njit(cache=True)
def _blurred_cov2d(c00, c01, c11, eps2d):
    """The 2D covariance plus ``eps2d`` on the diagonal: (det before, b00, b11, det > 0, det or 1, 1 / that)."""
    det_orig = c00 * c11 - c01 * c01
    b00 = c00 + eps2d
    b11 = c11 + eps2d
    det = b00 * b11 - c01 * c01
    det_ok = det > 0.0
    det_s = det if det_ok else 1.0
    return det_orig, b00, b11, det_ok, det_s, 1.0 / det_s


@njit(parallel=True, cache=True)
def project_fwd(means, quats, scales, opac, finite_mask, R, cam, fx, fy, cx, cy, lxn, lxp, lyn, lyp, near, far,
                eps2d, antialiased, aa_floor, ext_mode, ext_k, ext_cap, threshold, width, height, radius_max,
                out_m2d, out_conic, out_depth, out_opac, out_radii, out_visible, out_rel):
    n = means.shape[0]
    for i in prange(n):
        rel = np.empty(3)
        Rq = np.empty((3, 3))
        M = np.empty((3, 3))
        W = np.empty((2, 3))
        A = np.empty((2, 3))
        ok = _gaussian_ok(means, quats, scales, opac, finite_mask, i)
        (in_depth, xs, ys, zs, rz, ux, uy, tx, ty, c00, c01, c11,
         qw, qx, qy, qz, qinv, qgood) = _cov2d(i, ok, means, quats, scales, R, cam, fx, fy, lxn, lxp, lyn, lyp,
                                               near, far, rel, Rq, M, W, A)
        o = float(opac[i]) if ok else 0.0
        det_orig, b00, b11, det_ok, det_s, inv = _blurred_cov2d(c00, c01, c11, eps2d)
        if antialiased:
            o = o * math.sqrt(max(det_orig / det_s, aa_floor))
        mx = fx * xs * rz + cx
        my = fy * ys * rz + cy
        valid = in_depth and det_ok and o >= threshold
        rx = 0.0
        ry = 0.0
        if valid:
            if ext_mode == EXTENT_OPACITY:
                ratio = o / threshold
                if not ratio >= 1.0:
                    ratio = 1.0
                k = min(math.sqrt(2.0 * math.log(ratio)), ext_cap)
            else:
                k = ext_k
            rx = math.ceil(k * math.sqrt(max(b00, 0.0)))
            ry = math.ceil(k * math.sqrt(max(b11, 0.0)))
            if rx < 0.0:
                rx = 0.0
            elif rx > radius_max:
                rx = radius_max
            if ry < 0.0:
                ry = 0.0
            elif ry > radius_max:
                ry = radius_max
            inside = (mx + rx > 0.0) and (mx - rx < width) and (my + ry > 0.0) and (my - ry < height)
            valid = inside and (rx > 0.0 or ry > 0.0) and _isfinite(mx) and _isfinite(my)
        out_m2d[i, 0] = mx
        out_m2d[i, 1] = my
        out_conic[i, 0] = b11 * inv
        out_conic[i, 1] = -c01 * inv
        out_conic[i, 2] = b00 * inv
        out_depth[i] = zs
        out_opac[i] = o if valid else 0.0
        out_radii[i, 0] = np.int32(rx) if valid else 0
        out_radii[i, 1] = np.int32(ry) if valid else 0
        out_visible[i] = valid
        for a in range(3):
            out_rel[i, a] = rel[a]


@njit(parallel=True, cache=True)
def project_bwd(means, quats, scales, opac, finite_mask, R, cam, fx, fy, cx, cy, lxn, lxp, lyn, lyp, near, far,
                eps2d, antialiased, aa_floor, visible, g_m2d, g_conic, g_depth, g_opac, g_rel,
                d_means, d_quats, d_scales, d_opac):
    """Gradients w.r.t. means, quats, scales, opacities of project_fwd's differentiable outputs."""
    n = means.shape[0]
    for i in prange(n):
        rel = np.empty(3)
        Rq = np.empty((3, 3))
        M = np.empty((3, 3))
        W = np.empty((2, 3))
        A = np.empty((2, 3))
        gA = np.empty((2, 3))
        gM = np.empty((3, 3))
        gR = np.empty((3, 3))
        ok = _gaussian_ok(means, quats, scales, opac, finite_mask, i)
        (in_depth, xs, ys, zs, rz, ux, uy, tx, ty, c00, c01, c11,
         qw, qx, qy, qz, qinv, qgood) = _cov2d(i, ok, means, quats, scales, R, cam, fx, fy, lxn, lxp, lyn, lyp,
                                               near, far, rel, Rq, M, W, A)
        o = float(opac[i]) if ok else 0.0
        det_orig, b00, b11, det_ok, det_s, inv = _blurred_cov2d(c00, c01, c11, eps2d)
        # opacity (masked by visibility) and antialiasing compensation
        g_o2 = float(g_opac[i]) if visible[i] else 0.0
        g_det_orig = 0.0
        g_det_s = 0.0
        if antialiased:
            r = det_orig / det_s
            comp = math.sqrt(max(r, aa_floor))
            g_o = g_o2 * comp
            if r >= aa_floor:
                g_r = g_o2 * o * 0.5 / comp
                g_det_orig = g_r / det_s
                g_det_s = -g_r * det_orig / (det_s * det_s)
        else:
            g_o = g_o2
        # conic = (b11, -c01, b00) / det_s
        gc0 = float(g_conic[i, 0])
        gc1 = float(g_conic[i, 1])
        gc2 = float(g_conic[i, 2])
        g_b11 = gc0 * inv
        g_c01 = -gc1 * inv
        g_b00 = gc2 * inv
        g_inv = gc0 * b11 - gc1 * c01 + gc2 * b00
        g_det_s += -g_inv * inv * inv
        g_det = g_det_s if det_ok else 0.0
        g_b00 += g_det * b11
        g_b11 += g_det * b00
        g_c01 += -2.0 * c01 * g_det
        g_c00 = g_b00 + g_det_orig * c11
        g_c11 = g_b11 + g_det_orig * c00
        g_c01 += -2.0 * c01 * g_det_orig
        # cov = A A^T
        for b in range(3):
            gA[0, b] = 2.0 * g_c00 * A[0, b] + g_c01 * A[1, b]
            gA[1, b] = 2.0 * g_c11 * A[1, b] + g_c01 * A[0, b]
        # A = W M
        gJ00 = 0.0
        gJ02 = 0.0
        gJ11 = 0.0
        gJ12 = 0.0
        for k in range(3):
            gw0 = gA[0, 0] * M[k, 0] + gA[0, 1] * M[k, 1] + gA[0, 2] * M[k, 2]
            gw1 = gA[1, 0] * M[k, 0] + gA[1, 1] * M[k, 1] + gA[1, 2] * M[k, 2]
            # W = J R: W[0,k] = J00 R0k + J02 R2k; W[1,k] = J11 R1k + J12 R2k
            gJ00 += gw0 * R[0, k]
            gJ02 += gw0 * R[2, k]
            gJ11 += gw1 * R[1, k]
            gJ12 += gw1 * R[2, k]
        for k in range(3):
            for b in range(3):
                gM[k, b] = W[0, k] * gA[0, b] + W[1, k] * gA[1, b]
        # M = Rq diag(s)
        for b in range(3):
            s = float(scales[i, b]) if ok else 0.0
            gs = 0.0
            for k in range(3):
                gR[k, b] = gM[k, b] * s
                gs += gM[k, b] * Rq[k, b]
            d_scales[i, b] = gs if ok else 0.0
        # rotation matrix -> unit quaternion -> raw quaternion
        gw = 2.0 * (-qz * gR[0, 1] + qy * gR[0, 2] + qz * gR[1, 0] - qx * gR[1, 2] - qy * gR[2, 0] + qx * gR[2, 1])
        gx = 2.0 * (qy * gR[0, 1] + qz * gR[0, 2] + qy * gR[1, 0] - 2.0 * qx * gR[1, 1] - qw * gR[1, 2]
                    + qz * gR[2, 0] + qw * gR[2, 1] - 2.0 * qx * gR[2, 2])
        gy = 2.0 * (-2.0 * qy * gR[0, 0] + qx * gR[0, 1] + qw * gR[0, 2] + qx * gR[1, 0] + qz * gR[1, 2]
                    - qw * gR[2, 0] + qz * gR[2, 1] - 2.0 * qy * gR[2, 2])
        gz = 2.0 * (-2.0 * qz * gR[0, 0] - qw * gR[0, 1] + qx * gR[0, 2] + qw * gR[1, 0] - 2.0 * qz * gR[1, 1]
                    + qy * gR[1, 2] + qx * gR[2, 0] + qy * gR[2, 1])
        if qgood:
            dot = qw * gw + qx * gx + qy * gy + qz * gz
            d_quats[i, 0] = (gw - qw * dot) * qinv
            d_quats[i, 1] = (gx - qx * dot) * qinv
            d_quats[i, 2] = (gy - qy * dot) * qinv
            d_quats[i, 3] = (gz - qz * dot) * qinv
        else:
            for a in range(4):
                d_quats[i, a] = 0.0
        # Jacobian entries and the 2D mean -> camera-space point
        rz2 = rz * rz
        g_rz = fx * gJ00 + fy * gJ11
        g_tx = -fx * rz2 * gJ02
        g_ty = -fy * rz2 * gJ12
        g_rz2 = -fx * tx * gJ02 - fy * ty * gJ12
        g_rz += 2.0 * rz * g_rz2
        gm0 = float(g_m2d[i, 0])
        gm1 = float(g_m2d[i, 1])
        g_xs = fx * rz * gm0
        g_ys = fy * rz * gm1
        g_rz += fx * xs * gm0 + fy * ys * gm1
        g_zs = float(g_depth[i])
        # tx = zs clamp(xs rz, -lxn, lxp)
        g_zs += min(max(ux, -lxn), lxp) * g_tx
        if ux >= -lxn and ux <= lxp:
            g_ux = zs * g_tx
            g_xs += g_ux * rz
            g_rz += g_ux * xs
        g_zs += min(max(uy, -lyn), lyp) * g_ty
        if uy >= -lyn and uy <= lyp:
            g_uy = zs * g_ty
            g_ys += g_uy * rz
            g_rz += g_uy * ys
        g_zs += -g_rz * rz * rz
        if not in_depth:
            g_xs = 0.0
            g_ys = 0.0
            g_zs = 0.0
        # p = R rel, rel = m - c
        for a in range(3):
            gm = R[0, a] * g_xs + R[1, a] * g_ys + R[2, a] * g_zs + float(g_rel[i, a])
            d_means[i, a] = gm if ok else 0.0
        d_opac[i] = g_o if ok else 0.0


@njit(cache=True, inline="always")
def _unit_dir(dirs, i):
    """normalize_dirs: (x, y, z, inv_norm, differentiable)."""
    x = float(dirs[i, 0])
    y = float(dirs[i, 1])
    z = float(dirs[i, 2])
    if not (_isfinite(x) and _isfinite(y) and _isfinite(z)):
        return 0.0, 0.0, 0.0, 1.0, False
    n2 = x * x + y * y + z * z
    if not n2 > 0.0:
        return 0.0, 0.0, 0.0, 1.0, False
    inv = 1.0 / math.sqrt(n2)
    return x * inv, y * inv, z * inv, inv, True


@njit(cache=True, inline="always")
def _sh_basis(degree, x, y, z, b):
    b[0] = C0
    if degree >= 1:
        b[1] = -C1 * y
        b[2] = C1 * z
        b[3] = -C1 * x
        if degree >= 2:
            xx = x * x
            yy = y * y
            zz = z * z
            b[4] = C2_0 * (x * y)
            b[5] = C2_1 * (y * z)
            b[6] = C2_2 * (2.0 * zz - xx - yy)
            b[7] = C2_3 * (x * z)
            b[8] = C2_4 * (xx - yy)
            if degree >= 3:
                b[9] = C3_0 * y * (3.0 * xx - yy)
                b[10] = C3_1 * (x * y) * z
                b[11] = C3_2 * y * (4.0 * zz - xx - yy)
                b[12] = C3_3 * z * (2.0 * zz - 3.0 * xx - 3.0 * yy)
                b[13] = C3_4 * x * (4.0 * zz - xx - yy)
                b[14] = C3_5 * z * (xx - yy)
                b[15] = C3_6 * x * (xx - 3.0 * yy)


@njit(parallel=True, cache=True)
def sh_fwd(degree, sh, dirs, rows, clamp, out):
    """out[j, c] = sum_k basis_k(normalize(dirs[i])) sh[i, k, c] for i = rows[j]; clamp: max(out + 0.5, 0).

    ``rows`` picks the Gaussians (the visible ones of a frame) from the full arrays, so that no
    gathered copy of the coefficients is made.
    """
    K = (degree + 1) * (degree + 1)
    C = sh.shape[2]
    for j in prange(rows.shape[0]):
        i = rows[j]
        b = np.empty(16)
        x, y, z, inv, good = _unit_dir(dirs, i)
        _sh_basis(degree, x, y, z, b)
        for c in range(C):
            v = 0.0
            for k in range(K):
                v += b[k] * float(sh[i, k, c])
            if clamp:
                v = max(v + 0.5, 0.0)
            out[j, c] = v


@njit(parallel=True, cache=True)
def sh_bwd(degree, sh, dirs, pos, clamp, g_out, d_sh, d_dirs):
    """Gradients of sh_fwd w.r.t. the coefficients (d_sh, zero beyond the degree) and the directions.

    Every row of the full ``d_sh`` and ``d_dirs`` is written: row ``i`` gets output row ``pos[i]``'s
    gradient, or zeros where ``pos[i] < 0`` (a Gaussian ``rows`` did not pick), in one pass.
    """
    n = sh.shape[0]
    K = (degree + 1) * (degree + 1)
    C = sh.shape[2]
    for i in prange(n):
        j = pos[i]
        if j < 0:
            d_sh[i] = 0.0
            d_dirs[i] = 0.0
            continue
        b = np.empty(16)
        gb = np.zeros(16)
        gv = np.empty(C)
        x, y, z, inv, good = _unit_dir(dirs, i)
        _sh_basis(degree, x, y, z, b)
        for c in range(C):
            g = float(g_out[j, c])
            if clamp:
                v = 0.0
                for k in range(K):
                    v += b[k] * float(sh[i, k, c])
                if not v + 0.5 >= 0.0:
                    g = 0.0
            gv[c] = g
        for k in range(K):
            acc = 0.0
            for c in range(C):
                d_sh[i, k, c] = b[k] * gv[c]
                acc += float(sh[i, k, c]) * gv[c]
            gb[k] = acc
        for k in range(K, sh.shape[1]):
            for c in range(C):
                d_sh[i, k, c] = 0.0
        gx = 0.0
        gy = 0.0
        gz = 0.0
        if degree >= 1:
            gy += -C1 * gb[1]
            gz += C1 * gb[2]
            gx += -C1 * gb[3]
            if degree >= 2:
                xx = x * x
                yy = y * y
                zz = z * z
                gx += C2_0 * y * gb[4]
                gy += C2_0 * x * gb[4]
                gy += C2_1 * z * gb[5]
                gz += C2_1 * y * gb[5]
                gx += -2.0 * C2_2 * x * gb[6]
                gy += -2.0 * C2_2 * y * gb[6]
                gz += 4.0 * C2_2 * z * gb[6]
                gx += C2_3 * z * gb[7]
                gz += C2_3 * x * gb[7]
                gx += 2.0 * C2_4 * x * gb[8]
                gy += -2.0 * C2_4 * y * gb[8]
                if degree >= 3:
                    gx += C3_0 * 6.0 * x * y * gb[9]
                    gy += C3_0 * (3.0 * xx - 3.0 * yy) * gb[9]
                    gx += C3_1 * y * z * gb[10]
                    gy += C3_1 * x * z * gb[10]
                    gz += C3_1 * x * y * gb[10]
                    gx += C3_2 * (-2.0 * x * y) * gb[11]
                    gy += C3_2 * (4.0 * zz - xx - 3.0 * yy) * gb[11]
                    gz += C3_2 * 8.0 * y * z * gb[11]
                    gx += C3_3 * (-6.0 * x * z) * gb[12]
                    gy += C3_3 * (-6.0 * y * z) * gb[12]
                    gz += C3_3 * (6.0 * zz - 3.0 * xx - 3.0 * yy) * gb[12]
                    gx += C3_4 * (4.0 * zz - 3.0 * xx - yy) * gb[13]
                    gy += C3_4 * (-2.0 * x * y) * gb[13]
                    gz += C3_4 * 8.0 * x * z * gb[13]
                    gx += C3_5 * 2.0 * x * z * gb[14]
                    gy += C3_5 * (-2.0 * y * z) * gb[14]
                    gz += C3_5 * (xx - yy) * gb[14]
                    gx += C3_6 * (3.0 * xx - 3.0 * yy) * gb[15]
                    gy += C3_6 * (-6.0 * x * y) * gb[15]
        if good:
            dot = x * gx + y * gy + z * gz
            d_dirs[i, 0] = (gx - x * dot) * inv
            d_dirs[i, 1] = (gy - y * dot) * inv
            d_dirs[i, 2] = (gz - z * dot) * inv
        else:
            d_dirs[i, 0] = 0.0
            d_dirs[i, 1] = 0.0
            d_dirs[i, 2] = 0.0


@njit(parallel=True, cache=True)
def rows_finite(a, out):
    """out[i] = all entries of row i of the 2D array ``a`` are finite.

    Branch free (a vector loop at memory speed): ``inf * 0`` and ``nan * 0`` are NaN, and a NaN
    stays NaN through the sum, which is 0 exactly when every entry is finite.
    """
    for i in prange(a.shape[0]):
        s = 0.0
        for j in range(a.shape[1]):
            s += a[i, j] * 0.0
        out[i] = s == 0.0
