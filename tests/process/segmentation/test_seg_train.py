from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from helpers_seg import SCENE_COLORS, synthetic_scene, write_labelled_recording

from process.errors import ConfigError, StageError
from process.evaluate import confusion_iou, confusion_matrix, confusion_miou
from process.segmentation import SegmentationConfig, Segmenter
from process.segmentation.dataset import (
    IGNORE,
    LabelledImages,
    augment_pair,
    class_weights,
    color_jitter,
    load_labelled,
)
from process.segmentation.deeplab import build_model
from process.segmentation.train import EpochStats, TrainConfig, train
from process.segmentation.validation import normalise, recalibrate_batchnorm
from process.segmentation.weights import load_checkpoint

TINY = TrainConfig(
    arch="deeplabv3plus_lite_mobilenet_v3_small", short_side_px=96, crop_hw=(64, 96), batch_size=4,
    lr=5e-3, every_nth=1, threads=2,
)  # fmt: skip


def test_iou_matches_a_hand_computed_example() -> None:
    gt = np.array([[0, 0, 1, 1], [0, 0, 1, 1], [2, 2, 2, IGNORE]])
    pred = np.array([[0, 1, 1, 1], [0, 0, 1, 2], [2, 2, 0, 0]])
    conf = confusion_matrix(pred, gt, n_labels=3)
    # TP / (TP + FP + FN): label 0: 3/(3+1+1); label 1: 3/(3+1+1); label 2: 2/(2+1+1)
    assert confusion_iou(conf, classes=range(3)) == pytest.approx({0: 0.6, 1: 0.6, 2: 0.5})
    assert confusion_miou(conf, classes=range(3)) == pytest.approx(1.7 / 3)
    # By default 0 (unlabelled) is not a class: the mean is over labels 1-10.
    assert confusion_miou(conf) == pytest.approx(1.1 / 2)


def test_metrics_count_labels_in_prediction_or_truth() -> None:
    # One definition everywhere (process.evaluate): a label only predicted counts, with IoU 0.
    conf = confusion_matrix(np.array([0, 5, 4]), np.array([0, 0, 4]))
    assert confusion_iou(conf) == {4: 1.0, 5: 0.0}
    assert confusion_iou(conf, classes=range(11)) == {0: 0.5, 4: 1.0, 5: 0.0}
    assert confusion_miou(conf) == pytest.approx(0.5)


def test_augmentation_moves_colour_and_labels_together() -> None:
    rng = np.random.default_rng(0)
    color, labels = synthetic_scene(rng)
    for seed in range(5):
        c, lab = augment_pair(
            color, labels, crop_hw=(64, 80), scale_range=(0.5, 1.5), rng=np.random.default_rng(seed)
        )
        assert c.shape == (64, 80, 3) and lab.shape == (64, 80)
        for label in set(np.unique(lab)) - {
            IGNORE
        }:  # the scene's colours stay attached to their labels
            mean = c[lab == label].mean(axis=0)
            expected = SCENE_COLORS[int(label)]
            assert np.abs(mean - expected).max() < 40
        assert (c[lab == IGNORE] == 0).all()  # padding is black and not evaluated


def test_color_jitter_stays_in_range_and_changes_images() -> None:
    x = torch.rand(4, 3, 8, 8)
    y = color_jitter(x, strength=0.4, generator=torch.Generator().manual_seed(0))
    assert y.min() >= 0 and y.max() <= 1 and not torch.allclose(x, y)


def test_class_weights_favour_rare_labels() -> None:
    labels = np.zeros(1000, np.uint8)
    labels[:10] = 9
    w = class_weights(labels, power=1.0)
    assert w[9] > 1.0 > w[0]


def test_loading_needs_ground_truth_labels(recording: Path) -> None:
    with pytest.raises(StageError, match="ground_truth/labels"):
        load_labelled([recording], short_side_px=96)


def test_tiny_training_run_lowers_the_loss_and_writes_a_usable_checkpoint(tmp_path: Path) -> None:
    rec = write_labelled_recording(tmp_path / "train.mcap", frames=8, seed=1)
    val = write_labelled_recording(tmp_path / "val.mcap", frames=4, seed=2)
    seen: list[EpochStats] = []
    out = tmp_path / "tiny.safetensors"
    result = train(
        [rec], out=out, val=[val], epochs=6, seed=0, cfg=TINY, progress=False, on_epoch=seen.append
    )
    losses = [h.loss for h in result.history]
    assert len(seen) == 6 and losses[-1] < 0.7 * losses[0]
    assert all(h.val_miou is not None and 0 <= h.val_miou <= 1 for h in result.history)
    ckpt = load_checkpoint(out)
    assert ckpt.info["seed"] == 0 and ckpt.info["epoch"] == result.best_epoch
    assert ckpt.short_side_px == 96
    color, _ = synthetic_scene(np.random.default_rng(3))
    seg = Segmenter(SegmentationConfig(weights=str(out))).segment(color)
    assert seg.labels.shape == (96, 128)


def test_batchnorm_recalibration_sets_the_data_statistics() -> None:
    rng = np.random.default_rng(0)
    scenes = [synthetic_scene(rng) for _ in range(TINY.batch_size)]
    data = LabelledImages(np.stack([c for c, _ in scenes]), np.stack([lab for _, lab in scenes]))
    model = build_model(TINY.arch)
    stem = model.backbone.features[0]
    assert isinstance(stem, torch.nn.Sequential)
    conv, stem_bn = stem[0], stem[1]
    assert isinstance(stem_bn, torch.nn.BatchNorm2d) and stem_bn.running_mean is not None
    stem_bn.running_mean.fill_(100.0)  # stale statistics
    recalibrate_batchnorm(model, data, batches=1, batch_size=TINY.batch_size, rng=rng)
    x = torch.from_numpy(data.colors).permute(0, 3, 1, 2).float() / 255.0
    with torch.no_grad():
        expected = conv(normalise(x)).mean(dim=(0, 2, 3))
    assert torch.allclose(stem_bn.running_mean, expected, atol=1e-4)
    assert stem_bn.momentum is None  # cumulative; train() restores its momentum


def test_train_config_rejects_bad_values() -> None:
    with pytest.raises(ConfigError, match="arch"):
        TrainConfig(arch="vgg")
    with pytest.raises(ConfigError, match="scale_range"):
        TrainConfig(scale_range=(1.5, 1.0))


def test_a_checkpoint_names_its_training_frames_and_held_out_frames_stay_out(
    tmp_path: Path,
) -> None:
    """Issue 11: frames evaluated on must be kept out of training; the checkpoint says which."""
    from benchmarks.seg_models import check_held_out, stamp_ns

    rec = write_labelled_recording(tmp_path / "train.mcap", frames=4, seed=1)
    cfg = replace(TINY, bn_calibration_batches=0, threads=1)  # one step: 0.3 s
    with pytest.raises(ConfigError, match=r"\['train.mcap'\] are also training recordings"):
        train([rec], out=tmp_path / "x.safetensors", val=[rec], epochs=1, cfg=cfg, progress=False)
    out = tmp_path / "one.safetensors"
    train([rec], out=out, epochs=1, cfg=cfg, progress=False)
    (span,) = load_checkpoint(out).info["trained_frames"]
    first, last = 1_000_000_000, 1_000_000_000 + 3 * 33_333_333  # the helper's frame stamps
    assert span == {
        "recording": "train.mcap", "first_stamp_ns": first, "last_stamp_ns": last, "frames": 4,
        "taught": False,
    }  # fmt: skip
    info = load_checkpoint(out).info
    check_held_out(info, [first - 1, last + 1], "one")  # outside the trained frames: measured
    with pytest.raises(ValueError, match="span 1 held-out frame"):
        check_held_out(info, [last + 1, first + 33_333_333], "one")
    assert stamp_ns("1305031248.861712") == 1_305_031_248_861_712_000  # as the TUM importer
