"""`posenet viz`: pose-projection overlays for several checkpoints side by side (paper Fig. 6) and
feature-response heat maps before the geometric heads (paper Fig. 7)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import torch
import trimesh
from tqdm import tqdm

from posenet.checkpoint import load_checkpoint, load_model
from posenet.config import config_from_dict
from posenet.data import open_split
from posenet.data.layout import Instance, scan_split
from posenet.errors import PosenetError
from posenet.evaluation.evaluate import evaluate
from posenet.evaluation.featviz import model_feature_response
from posenet.predict.overlay import outline
from scgen.io import bop

GT_COLOUR = (255, 255, 255)  # BGR
PRED_COLOUR = (60, 220, 60)
TILE = 256


def silhouette_contours(mesh: trimesh.Trimesh, K: np.ndarray, R: np.ndarray, t: np.ndarray,
                        size: tuple[int, int]) -> list[np.ndarray]:  # fmt: skip
    """Outer contours of the model projected at pose (R, t) through the pinhole K."""
    uv = (mesh.vertices @ R.T + t) @ K.T
    return outline(uv[:, :2] / np.clip(uv[:, 2:3], 1e-6, None), np.asarray(mesh.faces), size)


def _crop_box(inst: Instance, pad: float = 1.4) -> tuple[int, int, int]:
    x, y, w, h = inst.bbox_obj
    side = int(max(w, h) * pad) + 8
    return int(x + w / 2 - side / 2), int(y + h / 2 - side / 2), side


def _square_crop(img: np.ndarray, x0: int, y0: int, side: int) -> np.ndarray:
    """A side x side crop (zero-padded outside the image), resized to TILE."""
    out = np.zeros((side, side, 3), np.uint8)
    h, w = img.shape[:2]
    xs, ys = max(0, x0), max(0, y0)
    xe, ye = min(w, x0 + side), min(h, y0 + side)
    if xe > xs and ye > ys:
        out[ys - y0 : ye - y0, xs - x0 : xe - x0] = img[ys:ye, xs:xe]
    return cv2.resize(out, (TILE, TILE), interpolation=cv2.INTER_AREA)


def _label(tile: np.ndarray, text: str) -> np.ndarray:
    cv2.putText(tile, text, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    return tile


def overlay_panel(data: Path, split: str, ckpts: list[Path], ids: list[int], workers: int = 0) -> np.ndarray:
    """Rows = samples; columns = input, then each checkpoint's predicted (green) vs GT (white) contour."""
    obj_id = config_from_dict(load_checkpoint(ckpts[0])["config"]).data.obj_id  # the object it was trained on
    instances = {i.im_id: i for i in scan_split(data, split, obj_id) if i.im_id in ids}
    missing = sorted(set(ids) - set(instances))
    if missing:
        raise PosenetError(f"sample(s) {missing} not in split '{split}' of {data}")
    mesh = bop.read_model_mesh(data, obj_id)
    preds = []
    for ckpt in ckpts:
        result = evaluate(data, ckpt, split, image_ids=set(ids), workers=workers)
        preds.append((result.variant, {r["im_id"]: r for r in result.records}))
    rows = []
    for im_id in ids:
        inst = instances[im_id]
        rgb = cv2.imread(str(inst.rgb), cv2.IMREAD_COLOR)
        x0, y0, side = _crop_box(inst)
        tiles = [_label(_square_crop(rgb, x0, y0, side), f"#{im_id} input")]
        gt = silhouette_contours(mesh, inst.K, inst.R, inst.t, inst.image_size)
        for variant, records in preds:
            img = rgb.copy()
            cv2.drawContours(img, gt, -1, GT_COLOUR, 1, cv2.LINE_AA)
            rec = records.get(im_id)
            if rec is not None:
                R = np.asarray(rec["R"]).reshape(3, 3)
                t = np.asarray(rec["t"])
                cv2.drawContours(img, silhouette_contours(mesh, inst.K, R, t, inst.image_size), -1,
                                 PRED_COLOUR, 1, cv2.LINE_AA)  # fmt: skip
                text = f"{variant} ADD {1000 * rec['add_m']:.1f} mm"
            else:
                text = f"{variant}: no prediction"
            tiles.append(_label(_square_crop(img, x0, y0, side), text))
        rows.append(np.hstack(tiles))
    return np.vstack(rows)


def heatmap_panel(data: Path, split: str, ckpts: list[Path], ids: list[int]) -> np.ndarray:
    """Rows = samples; columns = RoI input, then each checkpoint's feature-response map over the RoI."""
    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    columns: list[tuple[str, dict[int, np.ndarray], dict[int, np.ndarray]]] = []
    for ckpt in ckpts:
        model, state = load_model(ckpt, device)
        cfg = config_from_dict(state["config"])
        ds = open_split(data, split, cfg.data, model.config, train=False, image_ids=set(ids))
        maps, rois = {}, {}
        for k in tqdm(range(len(ds)), desc="features", unit="img", dynamic_ncols=True, leave=False):
            item = ds[k]
            im_id = int(item["key"][1])
            roi_img, coord = item["roi_img"][None].to(device), item["roi_coord2d"][None].to(device)
            heat = model_feature_response(model, roi_img, coord)
            maps[im_id] = heat[0].cpu().numpy()
            rois[im_id] = (item["roi_img"].permute(1, 2, 0).numpy()[..., ::-1] * 255).astype(np.uint8)
        columns.append((state["model_config"]["variant"], maps, rois))
    rows = []
    for im_id in ids:
        roi = cv2.resize(columns[0][2][im_id], (TILE, TILE))
        tiles = [_label(roi.copy(), f"#{im_id} RoI")]
        for variant, maps, _ in columns:
            heat = cv2.applyColorMap((cv2.resize(maps[im_id], (TILE, TILE)) * 255).astype(np.uint8),
                                     cv2.COLORMAP_JET)  # fmt: skip
            tiles.append(_label(cv2.addWeighted(roi, 0.45, heat, 0.55, 0), variant))
        rows.append(np.hstack(tiles))
    return np.vstack(rows)
