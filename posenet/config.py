"""Training configuration: dataclasses with the paper's values, the built-in `smoke` preset, file loading.

A config file (YAML or TOML) may name a base `preset` (paper or smoke) and override any field:

    preset: smoke
    variant: gap-gdrnet
    model: {head_channels: 32}
    data: {workers: 2, bg_prob: 0.0}
    optim: {epochs: 20, lr: 1e-3}

`preset`, `variant` and `model` are the arguments of `posenet.models.create_model(variant, preset,
**model)`: the variant fixes the modules (ggca, mecs, pgsa), `model` overrides any ModelConfig field of
the preset (the backbone included) without changing the modules; a file's `model` table is merged over
the preset's. Training starts from ImageNet weights: `model.pretrained` is 'imagenet' (timm's, downloaded)
in the paper preset and 'package' (the weights the EfficientNet-Lite0 package ships) in the CPU preset;
`pretrained: null` trains from random init. `to_dict()` is what is saved as
OUT/config.yaml; it reloads to the same configuration.
"""

from __future__ import annotations

import dataclasses
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from posenet.errors import PosenetError
from posenet.models import PRESETS, ModelConfig
from posenet.models.config import IMAGENET, PACKAGE
from scgen.io import NUMBER_FORM, load_yaml

AMP_MODES = ("auto", "off", "bf16", "fp16")  # optim.amp: posenet.training.amp resolves them
AUGMENTS = ("paper", "spnv2", "gdrnet-occlusion")  # data.augment: posenet.data.photometric's chains
# data.loader: per-sample workers, the packed cache with batch augmentation, or auto (posenet.training.
# fast_path: the cache on CUDA, where it was built for, the per-sample workers elsewhere)
LOADERS = ("samples", "cache", "auto")
AUTO = "auto"  # data.loader's and optim.compile's: decided by the device a run trains on
# what a value of each field type looks like in a config file, for the message of a wrongly typed one
EXPECTED_FORM = {float: NUMBER_FORM, int: "a whole number such as 8", bool: "true or false", str: "a string"}


@dataclass
class DataConfig:
    """Reading, cropping and augmenting samples (probabilities are per sample)."""

    obj_id: int = 1  # the object trained and evaluated (BOP obj_id; `--obj-id`)
    pad_scale: float = 1.5  # DZI: crop side = max(w, h) * pad_scale
    # > 0: training also skips instances this little visible (GDR-Net's configs: 0.0, or 0.2 for YCB-V;
    # GDRNPP's: 0.3)
    min_visib_fract: float = 0.0
    num_pm_points: int = 3000
    dzi_prob: float = 1.0  # scale/shift perturbation of the crop
    dzi_scale: float = 0.25
    dzi_shift: float = 0.25
    color_prob: float = 0.8  # brightness/contrast
    brightness: tuple[float, float] = (0.5, 1.5)
    contrast: tuple[float, float] = (0.5, 1.5)
    bg_prob: float = 0.5  # background replacement
    bg_from_dataset: float = 0.5  # share of replacements taken from other dataset images (else noise)
    bg_pool_size: int = 32  # target-free backgrounds each loader process keeps in memory
    # GDR-Net's TRUNCATE_FG: a background replacement also cuts away part of the visible target (0.8 of
    # the time; augment.draw_cut), and every target follows the cut visible mask
    truncate_fg: bool = False
    # photometric chain (data/photometric.py): paper (brightness/contrast, color_prob) | spnv2 |
    # gdrnet-occlusion (applied with color_prob)
    augment: str = "paper"
    # DataLoader worker processes per training process; on a CPU no more than the cores its threads leave
    # (posenet.training.train.loader_workers)
    workers: int = 4
    # samples: each worker decodes and augments whole samples (posenet.data.dataset); cache: a packed
    # cache decoded once under DATA/.posenet_cache, the crop, background and colour applied to the whole
    # batch on the training device (posenet.data.cache, batch_augment; augment 'paper', no truncate_fg);
    # auto: the cache on CUDA, samples elsewhere (posenet.training.fast_path). samples stays the default
    # until benchmarks/gpu_check.sh has measured auto on a GPU (docs/posenet.md)
    loader: str = "samples"
    # > 0: train on this many images of the train split, the first of one fixed shuffled order, so that a
    # smaller set lies inside a larger one (accuracy against data: benchmarks/figures/posenet_data_curve.py)
    train_images: int = 0


@dataclass
class LossConfig:
    """Loss weights (paper eq. 7-8) and the mask loss type: 'bce' (the mask channel as logits) or 'l1'
    (GDR-Net's default: L1 of the raw channel against the 0/1 mask; see losses.mask_loss)."""

    coord: float = 1.0
    mask: float = 1.0
    region: float = 1.1
    pm: float = 1.0
    cent: float = 1.0
    z: float = 1.0
    mask_type: str = "bce"


@dataclass
class OptimConfig:
    """Ranger (RAdam + Lookahead) and the per-iteration warmup + flat + cosine schedule."""

    lr: float = 2e-4
    weight_decay: float = 0.05
    # Adam's epsilon (GDRNPP's Ranger: 1e-5). While the from-scratch backbone's residual branches were closed
    # its gradients were 1e-7..1e-8 and 1e-5 throttled its updates ~1000x (docs/posenet.md)
    eps: float = 1e-8
    batch_size: int = 24  # global: split evenly over DDP processes
    epochs: int = 300
    warmup_iters: int = 1000
    warmup_factor: float = 0.001
    anneal_point: float = 0.72  # fraction of all iterations spent before the cosine decay starts
    seed: int = 0
    # CPU threads for training (0: OMP_NUM_THREADS where set, else one per core); pinned so a run's losses
    # are reproducible
    threads: int = 0
    log_every: int = 10  # TensorBoard scalar interval (steps)
    ckpt_every: int = 1  # epochs between rewrites of OUT/last.pt (it is always written when a run stops)
    # mixed precision (posenet.training.amp): auto (bf16 on a CUDA GPU that has it, else float32) | off |
    # bf16 | fp16
    amp: str = "auto"
    # Ranger's gradient centralisation (GDR-Net's default): each conv / FC weight's gradient minus its mean
    grad_centralization: bool = False
    # weight decay on norm weights and biases too, as Ranger does; False: timm's no-decay group for them
    decay_norms_biases: bool = False
    # the step's forward and losses through torch.compile (posenet.training.capture): on CUDA as CUDA graphs
    # (mode reduce-overhead), for a GPU that idles between eager mode's kernel launches; one process only;
    # auto: compiled on CUDA in one process, eager elsewhere (posenet.training.fast_path)
    compile: bool | str = False


@dataclass
class TrainConfig:
    preset: str = "paper"
    variant: str = "gdrnet"
    # ModelConfig field overrides of create_model; the paper trains from timm's ImageNet weights
    model: dict[str, Any] = field(default_factory=lambda: {"pretrained": IMAGENET})
    data: DataConfig = field(default_factory=DataConfig)
    loss: LossConfig = field(default_factory=LossConfig)
    optim: OptimConfig = field(default_factory=OptimConfig)

    def model_config(self) -> ModelConfig:
        """The configuration `create_model(variant, preset, **model)` builds (validated there)."""
        return ModelConfig.create(self.variant, self.preset, **self.model)

    def to_dict(self) -> dict[str, Any]:
        """JSON/YAML-able; `resolved_model` (every ModelConfig field) is informational, ignored on load."""
        d = {k: plain(v) for k, v in dataclasses.asdict(self).items()}
        d["resolved_model"] = self.model_config().to_dict()
        return d

    def to_yaml(self) -> str:
        return yaml.safe_dump(self.to_dict(), sort_keys=False)


def plain(value: Any) -> Any:
    """Tuples as lists, recursively: what YAML and JSON write and read back."""
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    return list(value) if isinstance(value, tuple) else value


def smoke_config() -> TrainConfig:
    """Reduced CPU preset: the smoke model preset, small batches, short warmup, few loader processes."""
    return TrainConfig(
        preset="smoke",
        model={"pretrained": PACKAGE},  # ImageNet Lite0 without a download (posenet.models.backbone)
        data=DataConfig(workers=2, bg_pool_size=8),
        # lr 1e-3: from the ImageNet Lite0, coord left its plateau sooner than at 3e-4 (0.478 vs 0.501 at step
        # 2500; issue 20); 120 epochs of the 700-image benchmark set (10440 steps at ~6 steps/s) fill the
        # 35-minute CPU budget
        # float32 unless asked (optim.amp), also on a GPU
        optim=OptimConfig(batch_size=8, epochs=120, warmup_iters=50, lr=1e-3, log_every=1, amp="off"),
    )


def load_config(
    name_or_path: str,
    variant: str | None = None,
    epochs: int | None = None,
    obj_id: int | None = None,
    amp: str | None = None,
) -> TrainConfig:
    """A preset name or a YAML/TOML file, then the command-line overrides; validated."""
    raw = {"preset": name_or_path} if name_or_path in PRESETS else read_config_file(Path(name_or_path))
    cfg = config_from_dict(raw)
    if variant is not None:
        cfg.variant = variant
    if epochs is not None:
        cfg.optim.epochs = epochs
    if obj_id is not None:
        cfg.data.obj_id = obj_id
    if amp is not None:
        cfg.optim.amp = amp
    _validate(cfg)
    return cfg


def config_from_dict(raw: dict[str, Any]) -> TrainConfig:
    """A TrainConfig from a file's (or a checkpoint's) dict: the named preset, then every given field."""
    raw = dict(raw)
    preset = raw.pop("preset", "paper")
    # another name than smoke keeps the paper's training values; ModelConfig.create refuses unknown ones
    cfg = smoke_config() if preset == "smoke" else TrainConfig(preset=preset)
    for key, value in raw.items():
        if key in ("data", "loss", "optim"):
            setattr(cfg, key, override_fields(getattr(cfg, key), value, key))
        elif key == "model":
            if not isinstance(value, dict):
                raise PosenetError("config 'model' must be a table")
            cfg.model = {**cfg.model, **value}
        elif key == "variant":
            cfg.variant = value
        elif key != "resolved_model":
            raise PosenetError(f"unknown config key {key!r}")
    _validate(cfg)
    return cfg


def read_config_file(path: Path) -> dict[str, Any]:
    if not path.is_file():
        raise PosenetError(f"config {str(path)!r} is neither a preset ({', '.join(PRESETS)}) nor a file")
    try:
        text = path.read_text()
        data = load_yaml(text) if path.suffix.lower() in (".yaml", ".yml") else tomllib.loads(text)
    except (yaml.YAMLError, tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise PosenetError(f"cannot parse config {path}: {str(exc).splitlines()[0]}") from exc
    if not isinstance(data, dict):
        raise PosenetError(f"config {path} must be a table of sections")
    return data


def override_fields(section: Any, values: Any, name: str) -> Any:
    if not isinstance(values, dict):
        raise PosenetError(f"config '{name}' must be a table")
    fields = {f.name: f for f in dataclasses.fields(section)}
    out = {}
    for key, value in values.items():
        if key not in fields:
            raise PosenetError(f"unknown config key '{name}.{key}'")
        default = getattr(section, key)
        if value == AUTO and "bool | str" in str(fields[key].type):  # a switch left to the device
            out[key] = value
            continue
        if value is None and "None" in str(fields[key].type):  # an optional field set to null
            out[key] = None
            continue
        if default is None:  # an optional path (e.g. a weights file): a string or null
            if value is not None and not isinstance(value, str):
                raise PosenetError(f"config '{name}.{key}' must be a path or null, got {value!r}")
            out[key] = value
            continue
        if isinstance(default, tuple):
            numbers = isinstance(value, (list, tuple)) and all(_is_number(v) for v in value)
            if not numbers or len(value) != len(default):
                form = f"a list of {len(default)} numbers such as [{', '.join(map(str, default))}]"
                raise PosenetError(f"config '{name}.{key}' must be {form}, got {value!r}")
            value = tuple(float(v) for v in value)
        elif isinstance(default, float) and _is_number(value):
            value = float(value)
        if type(value) is not type(default):
            expected = EXPECTED_FORM.get(type(default), type(default).__name__)
            raise PosenetError(f"config '{name}.{key}' must be {expected}, got {value!r}")
        out[key] = value
    return dataclasses.replace(section, **out)


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _validate(cfg: TrainConfig) -> None:
    cfg.model_config()
    d, o = cfg.data, cfg.optim
    for name in ("dzi_prob", "color_prob", "bg_prob", "bg_from_dataset", "min_visib_fract"):
        if not 0.0 <= getattr(d, name) <= 1.0:
            raise PosenetError(f"data.{name} must lie in [0, 1], got {getattr(d, name)}")
    if d.augment not in AUGMENTS:
        raise PosenetError(f"data.augment must be one of {', '.join(AUGMENTS)}, got {d.augment!r}")
    if d.loader not in LOADERS:
        raise PosenetError(f"data.loader must be one of {', '.join(LOADERS)}, got {d.loader!r}")
    if o.compile not in (True, False, AUTO):
        raise PosenetError(f"optim.compile must be true, false or {AUTO!r}, got {o.compile!r}")
    if d.loader == "cache" and (d.augment != "paper" or d.truncate_fg):
        raise PosenetError(
            "data.loader 'cache' applies the paper's augmentations only (data.augment 'paper', "
            "data.truncate_fg false): use data.loader 'samples' for the others"
        )
    if cfg.loss.mask_type not in ("bce", "l1"):
        raise PosenetError(f"loss.mask_type must be 'bce' or 'l1', got {cfg.loss.mask_type!r}")
    if min(o.batch_size, o.epochs, o.log_every, o.ckpt_every) < 1 or o.lr <= 0 or o.eps <= 0:
        raise PosenetError(
            "optim.batch_size, epochs, log_every, ckpt_every must be >= 1, optim.lr and optim.eps > 0"
        )
    if o.amp not in AMP_MODES:
        raise PosenetError(f"optim.amp must be one of {', '.join(AMP_MODES)}, got {o.amp!r}")
    if d.workers < 0 or o.threads < 0 or d.train_images < 0:
        raise PosenetError("data.workers, data.train_images and optim.threads must be >= 0")
    if not 0.0 <= o.anneal_point <= 1.0:
        raise PosenetError(f"optim.anneal_point must lie in [0, 1], got {o.anneal_point}")
