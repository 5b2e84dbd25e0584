"""The cache path's pixel work on a whole batch, as torch ops on the batch's device (the GPU when training
on one).

posenet.data.cache's workers draw every random number of a sample on the host, in the per-sample path's
order (dataset.PoseDataset), and turn them into integer source indices and weights that replicate
OpenCV's fixed-point arithmetic (cv2_indices): here only gathers and arithmetic remain. The result is
the per-sample path's item to uint8 rounding: bilinear crop and background view within 1/255 per
channel before the colour jitter, nearest-neighbour targets equal (tests/test_posenet_cache.py).

The one exception is the noise background's fine grain: drawn here with torch's generator, so it has the
same distribution (N(0, sigma) per pixel and channel) as augment.noise_background's but other values,
and the sample's later draws (stars, colour) differ in value but not in distribution.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor

# augment.noise_background's coarse grid has 2 .. 16 cells a side (rng.integers(2, 17))
MAX_CELLS = 16


def gather2d(img: Tensor, rows: Tensor, cols: Tensor) -> Tensor:
    """B x C x Ro x Co values of img (B x C x H x W) at rows (B x Ro) and cols (B x Co); 0 where an index is
    negative (outside the source: OpenCV's constant border)."""
    b, c, _, w = img.shape
    out = img.gather(2, rows.clamp(min=0)[:, None, :, None].expand(b, c, rows.shape[1], w))
    out = out.gather(3, cols.clamp(min=0)[:, None, None, :].expand(b, c, rows.shape[1], cols.shape[1]))
    valid = (rows >= 0)[:, None, :, None] & (cols >= 0)[:, None, None, :]
    return out * valid


def bilinear(img: Tensor, rows: Tensor, wy: Tensor, cols: Tensor, wx: Tensor) -> Tensor:
    """Separable bilinear resampling of uint8 img (B x C x H x W) rounded to whole levels (float32, 0-255):
    rows/cols (B x N x 2) are each output pixel's two source indices (-1: outside, weighs 0), wy/wx
    (B x N) the second one's weight. Rows first: each gather then moves uint8, and the column pass
    works on N rows only."""
    b, c, _, w = img.shape
    n = rows.shape[1]
    vertical = torch.zeros(b, c, n, w, device=img.device)
    for k, weight in enumerate((1 - wy, wy)):
        picked = img.gather(2, rows[..., k].clamp(min=0)[:, None, :, None].expand(b, c, n, w))
        vertical += picked * (weight * (rows[..., k] >= 0))[:, None, :, None]
    out = torch.zeros(b, c, n, cols.shape[1], device=img.device)
    for k, weight in enumerate((1 - wx, wx)):
        picked = vertical.gather(
            3, cols[..., k].clamp(min=0)[:, None, None, :].expand(b, c, n, cols.shape[1])
        )
        out += picked * (weight * (cols[..., k] >= 0))[:, None, None, :]
    return torch.round(out)


def noise_backgrounds(
    cells: Tensor, coarse: Tensor, sigma: Tensor, stars: Tensor, star_values: Tensor, res: int
) -> Tensor:
    """augment.noise_background for a batch (B x 3 x res x res float32 in [0, 1]): the cells x cells coarse
    colours (B x 3 x MAX_CELLS x MAX_CELLS, top-left used) upsampled bicubically (torch's and OpenCV's cubic
    are both a = -0.75, pixel-centre aligned, edge-replicated), grain N(0, sigma), then the stars (B x S x 2
    pixel positions x, y; -1 pads) set to their values (B x S)."""
    img = torch.empty(len(cells), 3, res, res, device=coarse.device)
    for n in cells.unique().tolist():
        pick = cells == n
        img[pick] = F.interpolate(
            coarse[pick, :, :n, :n], size=(res, res), mode="bicubic", align_corners=False
        )
    img += torch.randn_like(img) * sigma[:, None, None, None]
    b, s = torch.nonzero(stars[..., 0] >= 0, as_tuple=True)
    img[b, :, stars[b, s, 1], stars[b, s, 0]] = star_values[b, s, None]
    return img.clamp(0.0, 1.0)


def brightness_contrast(img: Tensor, apply: Tensor, contrast: Tensor, brightness: Tensor) -> Tensor:
    """augment.brightness_contrast per sample where `apply` (B bools): contrast about each image's mean grey
    level, then a brightness gain; clipped."""
    mean = img.mean(dim=(1, 2, 3), keepdim=True)
    c, b = contrast[:, None, None, None], brightness[:, None, None, None]
    jittered = (((img - mean) * c + mean) * b).clamp(0.0, 1.0)
    return torch.where(apply[:, None, None, None], jittered, img)


def region_labels(xyz: Tensor, visible: Tensor, centres: Tensor) -> Tensor:
    """dataset.region_labels for a batch: xyz (B x 3 x r x r, metres), visible (B x r x r bools), centres
    (N x 3 float64) -> B x r x r int64, 1 + nearest centre where visible, else 0 (in float64, as there)."""
    labels = torch.zeros(visible.shape, dtype=torch.int64, device=xyz.device)
    pts = xyz.permute(0, 2, 3, 1)[visible].double()  # the visible pixels only, as there
    labels[visible] = ((pts[:, None, :] - centres[None]) ** 2).sum(-1).argmin(-1) + 1
    return labels


def augment_batch(raw: dict[str, Tensor], pool: Tensor, extent: Tensor, centres: Tensor) -> dict[str, Tensor]:
    """The training batch from posenet.data.cache's collated raw batch (on the device): the DZI crop of
    the image, background replacement (noise, or a view of a `pool` image: P x 3 x H x W uint8 RGB),
    brightness/contrast, and the nearest-neighbour targets; `extent` (3,) normalises xyz, `centres`
    (N x 3, float64) are the surface regions'."""
    res = raw["img_cols"].shape[1]
    img = bilinear(raw["window"][:, :3], raw["img_rows"], raw["img_wy"], raw["img_cols"], raw["img_wx"]) / 255
    bg_kind = raw["bg_kind"]  # 0 none, 1 noise, 2 pool view
    if bool((bg_kind > 0).any()):
        bg = torch.zeros_like(img)
        noise = bg_kind == 1
        if bool(noise.any()):
            bg[noise] = noise_backgrounds(
                raw["cells"][noise], raw["coarse"][noise], raw["sigma"][noise], raw["stars"][noise],
                raw["star_values"][noise], res,
            )  # fmt: skip
        view = bg_kind == 2
        if bool(view.any()):
            src = pool[raw["pool_index"][view]]
            bg[view] = (
                bilinear(
                    src, raw["bg_rows"][view], raw["bg_wy"][view], raw["bg_cols"][view], raw["bg_wx"][view]
                )
                / 255
            )
        keep = gather2d(raw["window"][:, 3:] & 1, raw["keep_rows"], raw["keep_cols"]) > 0
        img = torch.where(keep | (bg_kind == 0)[:, None, None, None], img, bg)
    img = brightness_contrast(img, raw["color"], raw["contrast"], raw["brightness"])
    masks = gather2d(raw["window"][:, 3:], raw["mask_rows"], raw["mask_cols"])[:, 0]
    visib, full = (masks & 1) > 0, (masks & 2) > 0
    xyz = gather2d(raw["xyz"], raw["xyz_rows"], raw["xyz_cols"])
    xyz_n = torch.where(visib[:, None], xyz / extent[None, :, None, None] + 0.5, 0.0)
    out = {k: v for k, v in raw.items() if k in PASSED_ON}
    return out | {
        "roi_img": img,
        "roi_xyz": xyz_n.float(),
        "roi_mask_visib": visib[:, None].float(),
        "roi_mask_full": full[:, None].float(),
        "roi_region": region_labels(xyz, visib, centres),
    }


# the items a worker makes whole (geometry and pose): passed on to the training step as they are
PASSED_ON = ("roi_coord2d", "K", "crop_center", "box_wh", "resize_ratio", "R", "t", "key", "site")
