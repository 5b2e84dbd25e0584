"""The field's photometric augmentation chains on a RoI crop, through albumentations (`data.augment`).

- `paper`: the paper's brightness/contrast jitter (augment.brightness_contrast, `data.color_prob`);
  nothing here.
- `spnv2`: SPNv2's training set (tpark94/spnv2, `build_transforms`), each at p 0.5: brightness/contrast
  (±0.2), coarse dropout (1-5 holes of 0.2-0.5 of the target box, inside it), a sun flare inside the
  target box, one of motion (3-9 px), median (3-7 px) or glass blur (sigma 0.5, delta 2), and Gaussian
  noise (std up to 40 of 255) or ISO noise (colour shift 0.1-0.5, intensity 0.5-1.0). It replaces the
  paper's colour jitter.
- `gdrnet-occlusion`: GDR-Net's LM-O / YCB-V imgaug chain (`COLOR_AUG_CODE`), applied with probability
  `data.color_prob` as GDR-Net's COLOR_AUG_PROB: coarse dropout (80 holes of 5 % of the side, ~20 % of
  the crop; imgaug drops 20 % of a 5 % grid), Gaussian blur (sigma up to 1.2), add ±25 (per channel 30 %
  of the time), invert (the whole image; imgaug inverts each channel with p 0.2), multiply 0.6-1.4 (per
  channel half the time), multiply 0.6-1.4, contrast 0.5-2.2; each at imgaug's `Sometimes` probability.

Each chain draws from a seed taken from the sample's generator, so a sample's augmentation is a function
of (seed, epoch, index) as the rest of the pipeline.
"""

from __future__ import annotations

import albumentations as A
import numpy as np

SPNV2_P = 0.5


def spnv2_chain(box: tuple[float, float, float, float], res: int) -> list[A.BasicTransform]:
    """SPNv2's transforms for a res x res crop whose target box is `box` (x0, y0, x1, y1, normalised)."""
    return [
        A.RandomBrightnessContrast(brightness_limit=0.2, contrast_limit=0.2, p=SPNV2_P),
        A.ConstrainedCoarseDropout(
            num_holes_range=(1, 5),
            hole_height_range=(0.2, 0.5),
            hole_width_range=(0.2, 0.5),
            bbox_labels=["target"],
            p=SPNV2_P,
        ),  # fmt: skip
        A.RandomSunFlare(
            flare_roi=box, num_flare_circles_range=(1, 10), src_radius=max(4, res // 4), p=SPNV2_P
        ),
        A.OneOf(
            [
                A.MotionBlur(blur_limit=(3, 9)),
                A.MedianBlur(blur_limit=(3, 7)),
                A.GlassBlur(sigma=0.5, max_delta=2),
            ],
            p=SPNV2_P,
        ),
        A.OneOf(
            [
                A.GaussNoise(std_range=(0.0, 40 / 255)),
                A.ISONoise(color_shift=(0.1, 0.5), intensity=(0.5, 1.0)),
            ],
            p=SPNV2_P,
        ),
    ]


def gdrnet_occlusion_chain() -> list[A.BasicTransform]:
    """GDR-Net's LM-O imgaug chain in albumentations (approximations in the module docs)."""
    return [
        A.CoarseDropout(
            num_holes_range=(80, 80), hole_height_range=(0.05, 0.05), hole_width_range=(0.05, 0.05), p=0.5
        ),
        A.GaussianBlur(blur_limit=0, sigma_limit=(0.01, 1.2), p=0.5),
        A.OneOf(
            [
                A.RGBShift(r_shift_limit=25, g_shift_limit=25, b_shift_limit=25, p=0.3),
                A.RandomBrightnessContrast(brightness_limit=25 / 255, contrast_limit=0.0, p=0.7),
            ],
            p=0.5,
        ),
        A.InvertImg(p=0.3),
        A.OneOf(
            [A.MultiplicativeNoise((0.6, 1.4), per_channel=True), A.MultiplicativeNoise((0.6, 1.4))], p=0.5
        ),
        A.MultiplicativeNoise((0.6, 1.4), p=0.5),
        A.RandomBrightnessContrast(brightness_limit=0.0, contrast_limit=(-0.5, 1.2), p=0.5),
    ]


def composed(transforms: list[A.BasicTransform]) -> A.Compose:
    """The transforms in order, given the target's box: call with image=, bboxes=[box], labels=["target"].
    Seed its transforms after composing: a Compose gives them fresh seeds of its own."""
    return A.Compose(transforms, bbox_params=A.BboxParams(format="albumentations", label_fields=["labels"]))


def seed_each(transforms: list, rng: np.random.Generator) -> None:
    """A seed of its own for every transform, nested ones too. (albumentations' Compose(seed=s) gives each
    transform the same seed s, so transforms of equal p would all apply or all skip together.)"""
    for t in transforms:
        t.set_random_seed(int(rng.integers(2**31)))
        seed_each(list(getattr(t, "transforms", [])), rng)


def photometric(
    name: str, img: np.ndarray, box: tuple[float, float, float, float], rng: np.random.Generator
) -> np.ndarray:
    """Chain `name` (spnv2 or gdrnet-occlusion) on a float32 RGB crop in [0, 1] whose target box is `box`
    (x0, y0, x1, y1 normalised to the crop, clipped to it); the result is float32 in [0, 1]."""
    res = img.shape[0]
    if min(box[2] - box[0], box[3] - box[1]) < 1 / res:  # the box left the crop: the crop stands for it
        box = (0.0, 0.0, 1.0, 1.0)
    chain = spnv2_chain(box, res) if name == "spnv2" else gdrnet_occlusion_chain()
    compose = composed(chain)
    seed_each(chain, rng)
    uint8 = np.clip(np.rint(img * 255), 0, 255).astype(np.uint8)  # median blur wants 8 bits, as the renders
    out = compose(image=uint8, bboxes=[box], labels=["target"])["image"]
    return out.astype(np.float32) / 255
