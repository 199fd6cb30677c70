"""Fine-tune (or train from scratch) the segmentation network on labelled recordings."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch
from torch import nn
from tqdm import tqdm

from process.errors import ConfigError
from process.evaluate import confusion_iou, confusion_miou
from process.segmentation.dataset import (
    IGNORE,
    FrameSpan,
    LabelledImages,
    augment_pair,
    class_weights,
    color_jitter,
    load_labelled,
)
from process.segmentation.deeplab import PRESETS, DeepLab, build_model
from process.segmentation.distill import make_teacher
from process.segmentation.validation import (
    evaluate,
    normalise,
    recalibrate_batchnorm,
    set_bn_momentum,
)
from process.segmentation.weights import checkpoint_from_model, init_from, save_checkpoint

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class TrainConfig:
    """Hyper-parameters of `train`; defaults fit a CPU run on 640x480 simulated recordings."""

    arch: str = "deeplabv3plus_lite_mobilenet_v3_large"
    short_side_px: int = 240  # frames are stored at this short side; inference uses the same
    crop_hw: tuple[int, int] = (192, 256)
    scale_range: tuple[float, float] = (0.75, 1.35)
    jitter: float = 0.3
    batch_size: int = 8
    lr: float = 3e-3
    weight_decay: float = 1e-4
    class_balance: float = 0.5  # power of median-frequency class weights; 0 = plain CE
    every_nth: int = 1  # use every n-th labelled frame
    threads: int = 0  # torch CPU threads; 0 = torch's default
    channels_last: bool = True  # NHWC activations: about 1.5x faster on CPU
    bn_momentum: float = 0.1  # torchvision's 0.01 suits long ImageNet runs, not short ones
    bn_calibration_batches: int = 16  # recompute BatchNorm statistics before each evaluation
    half: bool = True  # store float16 weights (half the file size)

    def __post_init__(self) -> None:
        if self.arch not in PRESETS:
            raise ConfigError(f"train.arch must be one of {sorted(PRESETS)}, got {self.arch!r}")
        if not 32 <= self.short_side_px <= 2048 or min(self.crop_hw) < 32:
            raise ConfigError(
                f"train sizes too small: short side {self.short_side_px}, crop {self.crop_hw}"
            )
        if not 0 < self.scale_range[0] <= self.scale_range[1] <= 4:
            raise ConfigError(
                f"train.scale_range must satisfy 0 < lo <= hi <= 4, got {self.scale_range}"
            )
        if not 0 < self.bn_momentum <= 1 or self.bn_calibration_batches < 0:
            raise ConfigError(
                f"train.bn_momentum must be in (0, 1] and bn_calibration_batches >= 0, got "
                f"{self.bn_momentum}, {self.bn_calibration_batches}"
            )
        if not 1 <= self.batch_size <= 256 or not 0 < self.lr < 1 or self.every_nth < 1:
            raise ConfigError(
                "train batch_size/lr/every_nth out of range: "
                f"{self.batch_size}, {self.lr}, {self.every_nth}"
            )


@dataclass(frozen=True)
class EpochStats:
    """What one epoch did."""

    epoch: int
    loss: float
    seconds: float
    val_miou: float | None = None
    val_iou: dict[int, float] = field(default_factory=dict)


@dataclass(frozen=True)
class TrainResult:
    """The checkpoint written and the per-epoch history."""

    checkpoint: Path
    history: list[EpochStats]
    best_epoch: int


def train(
    recordings: Sequence[Path],
    *,
    out: Path,
    val: Sequence[Path] | None = None,
    epochs: int = 10,
    init: Path | None = None,
    seed: int = 0,
    cfg: TrainConfig | None = None,
    progress: bool = True,
    on_epoch: Callable[[EpochStats], None] | None = None,
    teacher: str | None = None,
    teacher_every_nth: int = 4,
) -> TrainResult:
    """Train on labelled recordings; write the best (by val mIoU) checkpoint to `out`.

    With `teacher` (a shipped real-image model, `distill.TEACHERS`), recordings without
    ground-truth labels train on the teacher's labels of every `teacher_every_nth` frame.
    """
    cfg = cfg or TrainConfig()
    if epochs < 1:
        raise ConfigError(f"epochs must be >= 1, got {epochs}")
    if cfg.threads:
        torch.set_num_threads(cfg.threads)
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    _refuse_shared_recordings(recordings, val or ())
    data = load_labelled(
        recordings,
        short_side_px=cfg.short_side_px,
        every_nth=cfg.every_nth,
        teacher=make_teacher(teacher, threads=cfg.threads) if teacher else None,
        teacher_every_nth=teacher_every_nth,
    )
    val_data = load_labelled(val, short_side_px=cfg.short_side_px) if val else None
    model = build_model(cfg.arch)
    if init is not None:
        missing = init_from(model, init)
        logger.info("initialised from %s; %d tensors left untrained", init, len(missing))
    if cfg.channels_last:
        model = model.to(memory_format=torch.channels_last)  # type: ignore[call-overload]
    set_bn_momentum(model, cfg.bn_momentum)
    steps_per_epoch = max(1, len(data) // cfg.batch_size)
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    sched = torch.optim.lr_scheduler.OneCycleLR(
        opt, max_lr=cfg.lr, total_steps=epochs * steps_per_epoch, pct_start=0.1
    )
    weights = class_weights(data.labels, power=cfg.class_balance) if cfg.class_balance else None
    loss_fn = nn.CrossEntropyLoss(weight=weights, ignore_index=IGNORE)
    gen = torch.Generator().manual_seed(seed)
    history: list[EpochStats] = []
    best = (-1.0, 0)
    for epoch in range(1, epochs + 1):
        t0 = time.perf_counter()
        loss = _epoch(
            model, data, cfg, opt, sched, loss_fn, rng, gen, steps_per_epoch, epoch, progress
        )
        recalibrate_batchnorm(
            model, data, batches=cfg.bn_calibration_batches, batch_size=cfg.batch_size, rng=rng,
            channels_last=cfg.channels_last,
        )  # fmt: skip
        set_bn_momentum(model, cfg.bn_momentum)
        stats = EpochStats(epoch, loss, time.perf_counter() - t0)
        if val_data is not None:
            conf = evaluate(model, val_data, batch_size=cfg.batch_size)
            stats = EpochStats(
                epoch, loss, stats.seconds, confusion_miou(conf), confusion_iou(conf)
            )
        history.append(stats)
        logger.info(
            "epoch %d: loss %.4f, val mIoU %s, %.0f s", epoch, loss, stats.val_miou, stats.seconds
        )
        if on_epoch is not None:
            on_epoch(stats)
        score = stats.val_miou if stats.val_miou is not None else float(epoch)
        if score >= best[0]:
            best = (score, epoch)
            _save(
                model, out, cfg=cfg, seed=seed, recordings=recordings, val=val, stats=stats,
                teacher=teacher, sources=data.sources,
            )  # fmt: skip
    return TrainResult(Path(out), history, best[1])


def _refuse_shared_recordings(recordings: Sequence[Path], val: Sequence[Path]) -> None:
    """Refuse validation recordings that are also training recordings (not held out)."""
    shared = {Path(p).resolve() for p in recordings} & {Path(p).resolve() for p in val}
    if shared:
        raise ConfigError(
            f"--val recording(s) {sorted(p.name for p in shared)} are also training recordings; "
            "validate on recordings kept out of training"
        )


def _epoch(
    model: DeepLab,
    data: LabelledImages,
    cfg: TrainConfig,
    opt: torch.optim.Optimizer,
    sched: torch.optim.lr_scheduler.LRScheduler,
    loss_fn: nn.Module,
    rng: np.random.Generator,
    gen: torch.Generator,
    steps: int,
    epoch: int,
    progress: bool,
) -> float:
    model.train()
    order = rng.permutation(len(data))
    total = 0.0
    bar = tqdm(
        range(steps), desc=f"epoch {epoch}", unit="batch", disable=not progress, dynamic_ncols=True
    )
    for step in bar:
        idx = order[step * cfg.batch_size : (step + 1) * cfg.batch_size]
        images, labels = _batch(data, idx, cfg, rng, gen)
        loss = loss_fn(model(images), labels)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        sched.step()
        value = float(loss.detach())
        total += value
        bar.set_postfix(loss=f"{value:.3f}")
    return total / steps


def _batch(
    data: LabelledImages,
    idx: np.ndarray,
    cfg: TrainConfig,
    rng: np.random.Generator,
    gen: torch.Generator,
) -> tuple[torch.Tensor, torch.Tensor]:
    pairs = [
        augment_pair(
            data.colors[i],
            data.labels[i],
            crop_hw=cfg.crop_hw,
            scale_range=cfg.scale_range,
            rng=rng,
        )
        for i in idx
    ]
    images = torch.from_numpy(np.stack([p[0] for p in pairs])).permute(0, 3, 1, 2).float() / 255.0
    if cfg.jitter:
        images = color_jitter(images, strength=cfg.jitter, generator=gen)
    labels = torch.from_numpy(np.stack([p[1] for p in pairs])).long()
    memory = torch.channels_last if cfg.channels_last else torch.contiguous_format
    return normalise(images).contiguous(memory_format=memory), labels


def _save(
    model: DeepLab,
    out: Path,
    *,
    cfg: TrainConfig,
    seed: int,
    recordings: Sequence[Path],
    val: Sequence[Path] | None,
    stats: EpochStats,
    teacher: str | None = None,
    sources: Sequence[FrameSpan] = (),
) -> None:
    info = {
        "trained_by": "process.segmentation.train",
        "epoch": stats.epoch,
        "seed": seed,
        "train_config": asdict(cfg),
        "recordings": [Path(p).name for p in recordings],
        "val_recordings": [Path(p).name for p in val or []],
        "val_miou": stats.val_miou,
        "teacher": teacher,
        # the frames trained on, per recording: a benchmark refuses to evaluate on them
        "trained_frames": [asdict(span) for span in sources],
    }
    ckpt = checkpoint_from_model(model, short_side_px=cfg.short_side_px, info=info)
    save_checkpoint(ckpt, Path(out), half=cfg.half)
