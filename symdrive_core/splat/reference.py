"""Vectorised pure-torch implementation of the same rasterizer maths (reference and benchmark baseline).

Everything is torch tensor code: tile lists are built with ``repeat_interleave`` and a sort, and
each chunk of tiles is composited as padded ``[tiles, 256 pixels, L Gaussians]`` tensors with a
cumulative product for transmittance. Differentiable by autograd (each chunk is checkpointed so
memory stays bounded). Use it through ``rasterize(..., backend="torch")``.
"""

from __future__ import annotations

import torch
from torch.utils.checkpoint import checkpoint

from ..conventions import PIXEL_CENTER_OFFSET
from .constants import ALPHA_MAX, T_STOP, TILE_SIZE


def tile_lists_torch(means2d, radii, depths, width: int, height: int, tile_size: int = TILE_SIZE):
    """(offsets [n_tiles+1], ids [n_isect]) with each tile's ids sorted by depth (stable)."""
    tiles_x = (width + tile_size - 1) // tile_size
    tiles_y = (height + tile_size - 1) // tile_size
    n_tiles = tiles_x * tiles_y
    dev = means2d.device
    m = means2d.shape[0]
    if m == 0:
        return torch.zeros(n_tiles + 1, dtype=torch.int64, device=dev), torch.zeros(0, dtype=torch.int64,
                                                                                    device=dev)
    mx, my = means2d.detach().double().unbind(-1)
    rx, ry = radii.double().unbind(-1)
    x0 = torch.clamp(torch.floor((mx - rx) / tile_size), 0, tiles_x).long()
    x1 = torch.clamp(torch.ceil((mx + rx) / tile_size), 0, tiles_x).long()
    y0 = torch.clamp(torch.floor((my - ry) / tile_size), 0, tiles_y).long()
    y1 = torch.clamp(torch.ceil((my + ry) / tile_size), 0, tiles_y).long()
    nx = x1 - x0
    cnt = nx * (y1 - y0)
    cnt = torch.where((rx > 0) | (ry > 0), cnt, torch.zeros_like(cnt))
    order = torch.sort(depths.detach(), stable=True).indices
    rank = torch.empty_like(order)
    rank[order] = torch.arange(m, device=dev)
    gid = torch.repeat_interleave(torch.arange(m, device=dev), cnt)
    local = torch.arange(gid.numel(), device=dev) - torch.repeat_interleave(torch.cumsum(cnt, 0) - cnt, cnt)
    nxg = nx[gid]
    tile = (y0[gid] + local // nxg) * tiles_x + x0[gid] + local % nxg
    key = tile * m + rank[gid]
    perm = torch.sort(key).indices
    ids = gid[perm]
    counts = torch.bincount(tile, minlength=n_tiles)
    offsets = torch.zeros(n_tiles + 1, dtype=torch.int64, device=dev)
    offsets[1:] = torch.cumsum(counts, 0)
    return offsets, ids


def _composite_chunk(means2d, conics, opac, feats, onehot, g, mask, px, py, threshold):
    """Padded compositing of a chunk: g/mask [Tc, L], px/py [Tc, P] -> ([Tc,P,C], [Tc,P], [Tc,P,G])."""
    mg = means2d[g]  # [Tc, L, 2]
    cg = conics[g]
    dx = mg[:, None, :, 0] - px[:, :, None]
    dy = mg[:, None, :, 1] - py[:, :, None]
    a, b, c = cg[:, None, :, 0], cg[:, None, :, 1], cg[:, None, :, 2]
    sigma = 0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy
    valid = mask[:, None, :] & (sigma >= 0)
    sigma = torch.where(valid, sigma, torch.zeros_like(sigma))
    alpha = torch.clamp_max(opac[g][:, None, :] * torch.exp(-sigma), ALPHA_MAX)
    valid = valid & (alpha >= threshold)
    alpha = torch.where(valid, alpha, torch.zeros_like(alpha))
    one_m = 1.0 - alpha
    t_incl = torch.cumprod(one_m, -1)
    t_before = torch.cat([torch.ones_like(t_incl[..., :1]), t_incl[..., :-1]], -1)
    stop = valid & (t_incl <= T_STOP)
    keep = torch.cumsum(stop.to(torch.int32), -1) == 0
    w = torch.where(keep, alpha * t_before, torch.zeros_like(alpha))
    color = torch.einsum("tpl,tlc->tpc", w, feats[g])
    inst = torch.einsum("tpl,tlk->tpk", w, onehot[g]) if onehot.shape[1] else w.new_zeros(w.shape[:2] + (0,))
    return color, w.sum(-1), inst


def rasterize_pixels_torch(means2d, conics, opac, feats, groups, n_groups: int, width: int, height: int,
                           threshold: float, radii, depths, tile_size: int = TILE_SIZE, chunk_elems: int = 1 << 22):
    """Like the numba path: (features [H,W,C], alpha [H,W], instance [H,W,G], n_isect)."""
    dev = means2d.device
    dtype = feats.dtype
    C = feats.shape[1]
    G = int(n_groups)
    tiles_x = (width + tile_size - 1) // tile_size
    tiles_y = (height + tile_size - 1) // tile_size
    n_tiles = tiles_x * tiles_y
    offsets, ids = tile_lists_torch(means2d, radii, depths, width, height, tile_size)
    counts = offsets[1:] - offsets[:-1]
    if G > 0:
        onehot = torch.nn.functional.one_hot(groups.clamp_min(0), G).to(dtype) * (groups >= 0)[:, None].to(dtype)
    else:
        onehot = torch.zeros(means2d.shape[0], 0, dtype=dtype, device=dev)
    P = tile_size * tile_size
    lp = torch.arange(P, device=dev)
    lx, ly = (lp % tile_size).to(dtype), (lp // tile_size).to(dtype)
    colors, alphas, insts = [], [], []
    counts_l = counts.tolist()
    t = 0
    while t < n_tiles:
        # grow the chunk while the padded tensor stays under the budget
        L = max(counts_l[t], 1)
        e = t + 1
        while e < n_tiles and (e + 1 - t) * P * max(L, counts_l[e]) <= chunk_elems:
            L = max(L, counts_l[e])
            e += 1
        tt = torch.arange(t, e, device=dev)
        L = int(counts[t:e].max())
        tx, ty = tt % tiles_x, tt // tiles_x
        px = (tx[:, None] * tile_size).to(dtype) + lx[None] + PIXEL_CENTER_OFFSET
        py = (ty[:, None] * tile_size).to(dtype) + ly[None] + PIXEL_CENTER_OFFSET
        if L == 0 or ids.numel() == 0:
            colors.append(feats.new_zeros(e - t, P, C) + 0.0 * feats.sum())
            alphas.append(feats.new_zeros(e - t, P))
            insts.append(feats.new_zeros(e - t, P, G))
        else:
            ar = torch.arange(L, device=dev)
            mask = ar[None] < counts[t:e, None]
            idx = torch.clamp(offsets[t:e, None] + ar[None], max=ids.numel() - 1)
            g = ids[idx]
            args = (means2d, conics, opac, feats, onehot, g, mask, px, py, threshold)
            if torch.is_grad_enabled() and any(x.requires_grad for x in (means2d, conics, opac, feats)):
                col, al, ins = checkpoint(_composite_chunk, *args, use_reentrant=False)
            else:
                col, al, ins = _composite_chunk(*args)
            colors.append(col)
            alphas.append(al)
            insts.append(ins)
        t = e

    def assemble(parts, ch):
        x = torch.cat(parts, 0).reshape(tiles_y, tiles_x, tile_size, tile_size, ch)
        x = x.permute(0, 2, 1, 3, 4).reshape(tiles_y * tile_size, tiles_x * tile_size, ch)
        return x[:height, :width]

    color = assemble(colors, C)
    alpha = assemble([a[..., None] for a in alphas], 1)[..., 0]
    inst = assemble(insts, G)
    return color, alpha, inst, int(offsets[-1])
