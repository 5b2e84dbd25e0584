"""The target's finish drawn per sample: its own stream, documented ranges, same labels, both backends."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from scgen.dataset.stats import compute_stats
from scgen.generator import Generator
from scgen.io.buffers import BACKGROUND_ID
from scgen.render.mitsuba.materials import CRINKLE_SLOPE, crinkle_normal_map, crinkle_normal_tensor
from scgen.render.sky.backgrounds import srgb_to_linear
from scgen.run.runner import RenderJob, run_render
from scgen.scenes import load_config
from scgen.scenes.finish import finish_group, finished, sample_finish
from scgen.scenes.materials import FINISH_RANGES, MATERIALS
from scgen.scenes.rng import factor_rng

TINY = (96, 72)
SKY = {"earth_map": "procedural", "stars": "procedural"}


def generator(finish: dict, backend: str = "mitsuba", seed: int = 5) -> Generator:
    overrides = {"finish": finish, "background": SKY}
    return Generator.load(seed=seed, resolution=TINY, backend=backend, quality="draft", camera="ideal",
                          overrides=overrides)  # fmt: skip


def test_draws_stay_in_their_documented_ranges_and_swap_at_their_rate():
    cfg = {"mode": "varied", "swap_prob": 0.25, "jitter": 1.0, "nominal_prob": 0.0}
    draws = [sample_finish(factor_rng(1, i, "finish"), cfg) for i in range(400)]
    assert draws[7] == sample_finish(factor_rng(1, 7, "finish"), cfg)  # a pure function of (seed, sample)
    swaps = np.mean([f["material"] != cls for d in draws for cls, f in d.items()])
    assert swaps == pytest.approx(0.25, abs=0.03)
    for d in draws:
        for cls, f in d.items():
            r, nominal = FINISH_RANGES[f["material"]], MATERIALS[f["material"]]
            assert r.roughness[0] <= f["roughness"] <= r.roughness[1]
            assert r.metallic[0] <= f["metallic"] <= r.metallic[1]
            assert r.detail[0] <= f["detail"] <= r.detail[1]
            base = np.asarray(f["base"])
            gain = base / np.asarray(nominal.base)
            assert np.all(gain <= r.brightness[1] * (1 + r.tint) + 1e-9)
            assert np.all((gain >= r.brightness[0] * (1 - r.tint) - 1e-9) | (base == 1.0))  # or clipped at 1
            assert finished(d, cls).roughness == f["roughness"] and finished(d, cls).detail == nominal.detail
    unjittered = sample_finish(factor_rng(1, 0, "finish"), {**cfg, "swap_prob": 0.0, "jitter": 0.0})
    assert all(finished(unjittered, cls) == MATERIALS[cls] for cls in MATERIALS)
    assert sample_finish(factor_rng(1, 0, "finish"), {**cfg, "mode": "nominal"}) == {}


def test_a_share_of_varied_samples_keeps_the_nominal_finish_and_moves_no_other_draw():
    cfg = {"mode": "varied", "swap_prob": 0.25, "jitter": 1.0, "nominal_prob": 0.0}
    never = [sample_finish(factor_rng(2, i, "finish"), cfg) for i in range(2000)]
    some = [sample_finish(factor_rng(2, i, "finish"), {**cfg, "nominal_prob": 0.05}) for i in range(2000)]
    nominal = sum(s == {} for s in some)
    assert abs(nominal - 100) < 3.5 * np.sqrt(2000 * 0.05 * 0.95)  # binomial(2000, 0.05)
    assert all(s == n for s, n in zip(some, never, strict=True) if s)  # every other sample as it was


def test_varied_finish_changes_the_target_and_nothing_else():
    nominal, varied = generator({"mode": "nominal"}), generator({"swap_prob": 0.5})
    with nominal, varied:
        changed = 0
        for i in range(3):
            a, b = nominal.sample(i), varied.sample(i)
            assert a.spec == dataclasses.replace(b.spec, finish={})
            assert finish_group(b.spec.finish) != "nominal"
            for name in ("mask", "mask_visib", "xyz"):
                assert np.array_equal(getattr(a.annotation, name), getattr(b.annotation, name)), name
            for name in ("depth", "instance", "target_depth", "normal", "sun_blocked"):
                assert np.array_equal(getattr(a.buffers, name), getattr(b.buffers, name)), name
            target = a.annotation.mask_visib
            near = cv2.dilate(target.astype(np.uint8), np.ones((7, 7), np.uint8)) > 0  # the film filter
            sky = (a.buffers.instance == BACKGROUND_ID) & ~near
            assert np.array_equal(a.buffers.rgb[sky], b.buffers.rgb[sky])  # the background as it was
            changed += int(np.abs(a.buffers.rgb[target].astype(int) - b.buffers.rgb[target]).mean() > 2)
        assert changed >= 2


def test_a_reused_mitsuba_bsdf_renders_what_a_new_one_would():
    """Mitsuba's target BSDFs are kept from sample to sample and set to each sample's finish in place
    (mitsuba.materials.TargetFinishes): sample 2 rendered after samples 0 and 1 equals sample 2 rendered
    by a fresh backend, whose BSDFs are built for it; the crinkle maps set in place come from one Dr.Jit
    kernel, bit for bit numpy's."""
    with generator({"swap_prob": 0.5}) as g:
        reused = [g.sample(i).buffers.rgb for i in range(3)][2]
    with generator({"swap_prob": 0.5}) as g:
        fresh = g.sample(2).buffers.rgb
    assert np.array_equal(reused, fresh)
    for slope in (0.0, 0.0137, CRINKLE_SLOPE, 0.05):
        tensor = np.asarray(crinkle_normal_tensor(slope))
        assert np.array_equal(tensor.view(np.uint32), crinkle_normal_map(slope).view(np.uint32)), slope


def test_blender_and_mitsuba_render_the_same_draws():
    """The finish moves each sample's target brightness the same way in both renderers (their BRDFs
    differ in detail, so the log brightness changes are compared by correlation and mean)."""
    close_up = {
        "distance": {"min_px": 450.0, "max_px": 500.0},
        "background": {**SKY, "probs": {"clean": 1.0}},
        "occluders": {"group_probs": {"none": 1.0}, "distractor_prob": 0.0},
        "shadow": {"caster_prob": 0.0},
        "illumination": {"probs": {"normal": 1.0}},
    }
    change = {}
    for backend in ("mitsuba", "blender"):
        lum = []
        for finish in ({"mode": "nominal"}, {"swap_prob": 0.0}):
            with Generator.load(seed=5, resolution=TINY, backend=backend, quality="draft", camera="ideal",
                                overrides={**close_up, "finish": finish}) as g:  # fmt: skip
                samples = [g.sample(i) for i in range(6)]
            lum.append([srgb_to_linear(s.buffers.rgb[s.annotation.mask_visib] / 255).mean() for s in samples])
        change[backend] = np.log(np.divide(*lum[::-1]))
    assert np.abs(change["mitsuba"]).max() > 0.15  # the draws are visible
    assert np.corrcoef(change["mitsuba"], change["blender"])[0, 1] > 0.6, change
    assert np.mean(change["mitsuba"]) == pytest.approx(np.mean(change["blender"]), abs=0.08), change


def test_stats_groups_samples_by_finish(tmp_path):
    cfg = load_config(overrides={"finish": {"swap_prob": 0.3}})
    groups = [finish_group(sample_finish(factor_rng(0, i, "finish"), cfg["finish"])) for i in range(6)]
    job = RenderJob(out=tmp_path / "ds", n=6, seed=0, backend="mitsuba", quality="draft", resolution=TINY,
                    overrides={"finish": {"swap_prob": 0.3}, "background": SKY})  # fmt: skip
    run_render(job, progress=False)
    counts = {}
    for split in compute_stats(tmp_path / "ds")["splits"].values():
        for group, n in split["factors"]["finish"].items():
            counts[group] = counts.get(group, 0) + n
    assert counts == {g: groups.count(g) for g in ("nominal", "varied", "swapped")}
    assert sum(counts.values()) == 6 and counts["varied"] + counts["swapped"] > 0
