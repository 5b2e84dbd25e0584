"""`posenet bench`: parameters, MACs and batch-1 latency of every variant, side by side on one device."""

from __future__ import annotations

import statistics
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from torch.utils.flop_counter import FlopCounterMode

from posenet.errors import PosenetError
from posenet.models import ModelConfig, PoseNet, create_model


@dataclass(frozen=True)
class BenchRow:
    """One variant's measurements (or the paper's figures for it)."""

    name: str
    backbone: str
    params_m: float
    macs_g: float
    latency_ms: float
    fps: float
    onnx_latency_ms: float | None = None  # the same forward through onnxruntime (CPU), when asked


# Paper Table 4 (RTX 4090, batch 1); the paper's "FLOPs" are MACs (reference gdrnet.md §6).
PAPER: dict[str, BenchRow] = {
    r.name: r
    for r in (
        BenchRow("gdrnet", "resnet34", 35.05, 11.42, 22.0, 45.45),
        BenchRow("convnext", "convnext_tiny", 47.22, 13.86, 24.3, 41.15),
        BenchRow("afr", "convnext_tiny", 47.67, 14.92, 27.0, 37.04),
        BenchRow("pgsa", "convnext_tiny", 47.29, 13.93, 24.8, 40.32),
        BenchRow("gap-gdrnet", "convnext_tiny", 47.75, 14.99, 27.8, 35.97),
    )
}


def resolve_device(choice: str) -> torch.device:
    """'auto' → cuda when available, else cpu; 'cuda' without a GPU is an error."""
    if choice == "auto":
        choice = "cuda" if torch.cuda.is_available() else "cpu"
    if choice == "cuda" and not torch.cuda.is_available():
        raise PosenetError("--device cuda requested but no CUDA device is available")
    return torch.device(choice)


def device_label(device: torch.device) -> str:
    """Human-readable device name for the report."""
    if device.type == "cuda":
        return f"cuda ({torch.cuda.get_device_name(device)})"
    return f"cpu ({torch.get_num_threads()} threads)"


def dummy_inputs(config: ModelConfig, device: torch.device) -> tuple[torch.Tensor, torch.Tensor]:
    """A batch-1 RoI image and coordinate map of the configured sizes."""
    gen = torch.Generator().manual_seed(0)
    img = torch.rand(1, 3, config.input_res, config.input_res, generator=gen)
    coord = torch.rand(1, 2, config.output_res, config.output_res, generator=gen)
    return img.to(device), coord.to(device)


@torch.no_grad()
def count_macs(model: PoseNet, inputs: tuple[torch.Tensor, torch.Tensor]) -> float:
    """Multiply-accumulates of one forward, = FlopCounterMode FLOPs / 2 (conv, linear, matmul ops)."""
    counter = FlopCounterMode(display=False)
    with counter:
        model(*inputs)
    return counter.get_total_flops() / 2


@torch.no_grad()
def measure_latency_ms(
    model: Callable[..., Any], inputs: tuple[torch.Tensor, torch.Tensor], warmup: int, iters: int
) -> float:
    """Median wall time of `iters` forwards of `model` (a network, or an onnxruntime graph's runner) after
    `warmup` untimed ones (device-synchronised)."""
    sync = torch.cuda.synchronize if inputs[0].is_cuda else (lambda: None)
    for _ in range(warmup):
        model(*inputs)
    sync()
    times = []
    for _ in range(iters):
        start = time.perf_counter()
        model(*inputs)
        sync()
        times.append(time.perf_counter() - start)
    return 1000 * statistics.median(times)


def onnx_latency_ms(
    model: PoseNet, inputs: tuple[torch.Tensor, torch.Tensor], warmup: int, iters: int
) -> float:
    """`measure_latency_ms` of the model exported to ONNX and run by onnxruntime on the CPU, with torch's
    intra-op thread count."""
    from posenet.export.onnx_export import (  # onnxscript's import costs ~0.6 s
        export_onnx,
        onnx_session,
        run_onnx,
    )

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "model.onnx"
        export_onnx(model, path)
        session = onnx_session(path)
    return measure_latency_ms(lambda *x: run_onnx(session, *x), inputs, warmup, iters)


def bench_variant(
    name: str,
    preset: str,
    device: torch.device,
    warmup: int,
    iters: int,
    backbone: str | None = None,
    onnx: bool = False,
) -> BenchRow:
    """Build variant `name` in `preset`'s configuration (on `backbone`, else the preset's) from random init
    and measure it in eval mode: only the architecture, no weights are needed. With `onnx` (CPU only),
    also its latency through onnxruntime."""
    model = create_model(name, preset, **({"backbone": backbone} if backbone else {})).to(device).eval()
    inputs = dummy_inputs(model.config, device)
    params = sum(p.numel() for p in model.parameters())
    macs = count_macs(model, inputs)
    latency = measure_latency_ms(model, inputs, warmup, iters)
    ort_ms = onnx_latency_ms(model, inputs, warmup, iters) if onnx else None
    return BenchRow(name, model.config.backbone, params / 1e6, macs / 1e9, latency, 1000 / latency, ort_ms)


def run_bench(
    names: list[str],
    device: torch.device,
    warmup: int = 3,
    iters: int = 10,
    smoke: bool = False,
    backbone: str | None = None,
    onnx: bool = False,
) -> list[BenchRow]:
    """Bench each variant in turn, freeing it before the next; `onnx` adds onnxruntime's latency (CPU)."""
    if onnx and device.type != "cpu":
        raise PosenetError("--onnx times onnxruntime on the CPU: bench with --device cpu")
    rows = []
    for name in names:
        rows.append(bench_variant(name, "smoke" if smoke else "paper", device, warmup, iters, backbone, onnx))
        if device.type == "cuda":
            torch.cuda.empty_cache()
    return rows


def _cell(value: float, paper: float | None, digits: int, bracket: bool) -> str:
    ours = f"{value:7.{digits}f}"
    if not bracket:
        return ours
    return f"{ours} ({paper:7.{digits}f})" if paper is not None else f"{ours} ({'-':>7})"


def format_report(rows: list[BenchRow], device: str, paper: dict[str, BenchRow] = PAPER) -> str:
    """Aligned table of ours with the paper's Table 4 in brackets, then the GAP/GDR latency ratio."""
    header = "; (paper Table 4, RTX 4090)" if paper else ""
    lines = [
        f"device: {device}; batch 1; MACs = FLOPs/2 from torch.utils.flop_counter{header}",
        f"{'variant':<11} {'backbone':<22} {'params M':>17} {'MACs G':>17} {'latency ms':>17} {'FPS':>17}"
        + (f" {'onnxruntime ms':>17}" if any(r.onnx_latency_ms is not None for r in rows) else ""),
    ]
    for r in rows:
        p = paper.get(r.name)
        cells = [
            _cell(getattr(r, field), p and getattr(p, field), digits, bracket=bool(paper))
            for field, digits in (("params_m", 2), ("macs_g", 2), ("latency_ms", 1), ("fps", 2))
        ]
        if r.onnx_latency_ms is not None:
            cells.append(f"{r.onnx_latency_ms:7.1f} ({1000 / r.onnx_latency_ms:6.1f} FPS)")
        lines.append(f"{r.name:<11} {r.backbone:<22} " + " ".join(f"{c:>17}" for c in cells))
    by_name = {r.name: r for r in rows}
    if {"gdrnet", "gap-gdrnet"} <= by_name.keys():
        ours = by_name["gap-gdrnet"].latency_ms / by_name["gdrnet"].latency_ms
        ratio = f"latency ratio gap-gdrnet / gdrnet: {ours:.2f}"
        if paper:
            ratio += f" (paper {paper['gap-gdrnet'].latency_ms / paper['gdrnet'].latency_ms:.2f}, GPU)"
        lines.append(ratio)
    return "\n".join(lines)
