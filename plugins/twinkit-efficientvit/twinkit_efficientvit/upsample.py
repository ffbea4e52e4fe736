"""Labels at input resolution from stride-8 logits: the argmax of their bilinear upsampling, computed cell by cell.

``F.interpolate(logits, size, mode="bilinear", align_corners=False).argmax(1)`` builds all 19 channels at full
resolution (about 40 % of the network's own time on a 1024x512 view). When the size is an even integer multiple
``f`` of the logits' size, each output pixel is a convex blend of the four logit vectors around it, and the
pixels of one cell of four share them. Where the four agree on their best class the blend's best class is that
class too (a convex combination keeps ``l_c >= l_j``), so :func:`upsample_argmax` blends only the cells whose
corners disagree (a few percent of a street view) and fills the rest. The borders take torch's rule (source
coordinates clamped at 0 and at the last row/column) through a replicated edge. The result equals torch's up
to float rounding of exact ties (tests/test_evit_upsample.py).
"""
from __future__ import annotations


def _cell_weights(f: int, dtype, device):
    """``(f*f, 4)`` blend weights per block pixel of the corners (top-left, top-right, bottom-left, bottom-right)."""
    import torch

    lam = (torch.arange(f, dtype=torch.float64) + 0.5) / f
    ly, lx = lam.view(f, 1), lam.view(1, f)
    w = torch.stack([(1 - ly) * (1 - lx), (1 - ly) * lx, ly * (1 - lx), ly * lx], dim=-1).reshape(f * f, 4)
    return w.to(dtype=dtype, device=device)


def upsample_argmax(logits, size: tuple[int, int]):
    """``logits (b, c, h, w)`` (torch) -> ``(b, H, W)`` uint8 argmax of their bilinear upsampling to ``size``
    (align_corners=False); the cell-wise path when ``H/h == W/w`` is an even integer, else torch's own."""
    import torch
    import torch.nn.functional as F

    b, c, h, w = logits.shape
    H, W = size
    f = H // h
    if c > 255 or f < 2 or f % 2 or H != f * h or W != f * w:
        return F.interpolate(logits, size=size, mode="bilinear", align_corners=False).argmax(1).to(torch.uint8)
    # channels last, so that every argmax runs along contiguous memory
    pad = F.pad(logits.float(), (1, 1, 1, 1), mode="replicate").permute(0, 2, 3, 1).contiguous()  # (b, h+2, w+2, c)
    best = pad.argmax(-1).to(torch.uint8)  # (b, h+2, w+2); the replicated edge is torch's clamped border
    tl, tr, bl, br = best[:, :-1, :-1], best[:, :-1, 1:], best[:, 1:, :-1], best[:, 1:, 1:]
    mixed = (tl != tr) | (tl != bl) | (tl != br)  # (b, h+1, w+1) cells whose corners disagree
    out = tl[:, :, None, :, None].expand(b, h + 1, f, w + 1, f).clone()
    bi, ti, ui = torch.nonzero(mixed, as_tuple=True)
    if len(bi):
        corners = torch.stack([pad[bi, ti, ui], pad[bi, ti, ui + 1], pad[bi, ti + 1, ui], pad[bi, ti + 1, ui + 1]],
                              dim=1)  # (m, 4, c)
        blocks = (_cell_weights(f, corners.dtype, corners.device) @ corners).argmax(-1)  # (m, f*f)
        out[bi, ti, :, ui, :] = blocks.to(torch.uint8).view(-1, f, f)
    half = f // 2
    return out.reshape(b, (h + 1) * f, (w + 1) * f)[:, half:half + H, half:half + W]
