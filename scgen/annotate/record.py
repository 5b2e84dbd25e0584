"""A sample's labels as the dataset records them: its metadata.csv row (the scene factors and the
measured labels, one column each) and its scene_gt_info entry. The writer files them; the labels are
computed here, from the SceneSpec and the Annotation, the stage that makes them."""

from __future__ import annotations

from typing import Any

import numpy as np

from scgen.annotate.annotate import Annotation, full_projection
from scgen.io import bop
from scgen.io.buffers import CameraRecord
from scgen.scenes.factors import FLARE_LABELS, noise_group, occluder_config, spec_key, viewpoint_cell
from scgen.scenes.finish import finish_group
from scgen.scenes.geometry import matrix_to_quat
from scgen.scenes.imaging import IDEAL_IMAGING, mid_grey_snr
from scgen.scenes.sky import background_holds, sky_labels
from scgen.scenes.spec import CameraSpec, SceneSpec


def exposure_ev(spec: SceneSpec, camera: CameraRecord | None) -> float:
    """The exposure the sample was recorded at: what the camera stage decided, else the spec's base."""
    return camera.exposure_ev if camera else spec.camera.exposure_ev


def metadata_row(
    spec: SceneSpec, ann: Annotation, split: str, scene_id: int, camera: CameraRecord | None = None
) -> dict[str, Any]:
    """One sample's metadata.csv row; `camera`: what the camera stage decided (None: the base exposure,
    no flare)."""
    R, t = spec.target.R_mat, spec.target.t_vec
    imaging = spec.imaging or IDEAL_IMAGING
    snr = mid_grey_snr(imaging.camera, imaging.gain)
    q = matrix_to_quat(R)
    sun = spec.sun.direction
    meta = {
        "sample_id": spec.index,
        "split": split,
        "scene_id": scene_id,
        "im_id": spec.index,
        "illumination": spec.sun.level,
        "sun_irradiance_w_m2": spec.sun.irradiance,
        "exposure_ev": exposure_ev(spec, camera),
        "sun_x": sun[0],
        "sun_y": sun[1],
        "sun_z": sun[2],
        "shadow": ann.shadow_label,
        "shadow_fraction": ann.shadow_fraction,
        "shadow_caster": int(spec.shadow_caster),
        "occlusion": ann.occlusion_group,
        "r_occ": ann.r_occ,
        "visib_fract": ann.visib_fract,
        "px_count_all": ann.px_count_all,
        "px_count_visib": ann.px_count_visib,
        "requested_occlusion": spec.requested_occlusion,
        "occluder_config": occluder_config(spec),
        "n_occluders": len(spec.occluders),
        "background": spec.background.kind,
        "background_holds": background_holds(spec.background.kind, spec.background.params),
        "distance_m": spec.distance_m,
        "tx": t[0],
        "ty": t[1],
        "tz": t[2],
        "qw": q[0],
        "qx": q[1],
        "qy": q[2],
        "qz": q[3],
        "viewpoint_cell": viewpoint_cell(R, t),
        "combination_key": spec_key(spec),
        "camera": imaging.camera.preset,
        "noise": noise_group(snr),
        "noise_gain": imaging.gain,
        "mid_grey_snr": "" if snr is None else snr,
        "psf_fwhm_px": imaging.psf_fwhm_px,
        "motion_blur_px": imaging.motion_blur_px,
        "motion_blur_deg": imaging.motion_blur_deg,
        "vignetting": imaging.vignetting,
        "chromatic_px": imaging.chromatic_px,
        "flare": FLARE_LABELS[int(bool(camera and camera.flare))],
        "saturated": camera.saturated if camera else 0.0,
        "finish": finish_group(spec.finish),
        **sky_labels(spec.background.params),
        **(spec.cone.labels() if spec.cone else {}),
        **(spec.sequence.labels() if spec.sequence else {}),
    }
    return meta


def gt_info_entry(camera: CameraSpec, ann: Annotation, vertices_cam: np.ndarray, faces: np.ndarray,
                  depth: np.ndarray, xyz_box: list[int] | None) -> dict[str, Any]:  # fmt: skip
    """The scene_gt_info.json entry of a rendered sample: the whole projection measured by
    `full_projection`, px_count_valid = silhouette pixels inside the image with a depth value."""
    px_count_all, bbox_obj = full_projection(ann.mask, camera, vertices_cam, faces)
    return bop.gt_info_entry(
        px_count_all, bbox_obj, ann.mask_visib, int((ann.mask & (depth > 0)).sum()), xyz_box
    )
