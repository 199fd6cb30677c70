from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt
import pytest
import torch
from helpers_seg import fake_torchvision_state, random_checkpoint, write_random_checkpoint

from capture.recording import VOC_TO_LABEL, RecordingReader
from process.errors import ConfigError, ModelError, StageError
from process.evaluate import confusion_iou, confusion_matrix, confusion_miou
from process.segmentation import Segmentation, SegmentationConfig, Segmenter
from process.segmentation.weights import label_matrix, save_checkpoint

VOC_CHAIR, VOC_BIRD, VOC_DOG = 9, 3, 12
TFLITE_MODELS = ["deeplabv3_mnv2_pascal_quant.tflite", "deeplabv3_mnv2_dm05_pascal_quant.tflite"]


@pytest.fixture(scope="module")
def small_ckpt(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_random_checkpoint(tmp_path_factory.mktemp("seg") / "small.safetensors", seed=2)


def _read_rgb(path: Path) -> npt.NDArray[np.uint8]:
    bgr = cv2.imread(str(path))
    assert bgr is not None, path
    return np.ascontiguousarray(bgr[:, :, ::-1], dtype=np.uint8)


def _image(height: int = 120, width: int = 160, seed: int = 0) -> npt.NDArray[np.uint8]:
    noise = np.random.default_rng(seed).integers(0, 255, (height, width, 3), dtype=np.uint8)
    return np.asarray(cv2.GaussianBlur(noise, (9, 9), 3), dtype=np.uint8)


def test_voc_classes_map_to_recording_labels() -> None:
    m = label_matrix(VOC_TO_LABEL)
    assert m.shape == (11, 21)
    assert m.sum(0).tolist() == [1.0] * 21  # every VOC class goes to exactly one label
    named = {0: 0, 9: 5, 11: 4, 15: 6, 16: 7, 18: 8, 20: 9, 5: 10}  # background, chair, table...
    assert all(m[label, voc] == 1 for voc, label in named.items())
    others = set(range(21)) - set(named)
    assert all(m[10, voc] == 1 for voc in others)  # every other VOC class is clutter


def test_voc_probabilities_sum_into_labels(tmp_path: Path) -> None:
    # A VOC network whose classifier is a constant: logit 2.5 for chair, 1 for the eight
    # classes 1-8 (all clutter), 0 elsewhere. Chair wins per class, clutter wins per label.
    state = fake_torchvision_state("deeplabv3_mobilenet_v3_large")
    state["classifier.4.weight"].zero_()
    bias = torch.zeros(21)
    bias[1:9], bias[VOC_CHAIR] = 1.0, 2.5
    state["classifier.4.bias"] = bias
    path = tmp_path / "voc.pth"
    torch.save(state, path)
    seg = Segmenter(SegmentationConfig(weights=str(path), short_side_px=64)).segment(_image())
    p = torch.softmax(bias, 0)
    clutter = [c for c in range(21) if VOC_TO_LABEL[c] == 10]  # 1-8, 10, 12-14, 17, 19
    assert (seg.labels == 10).all()
    assert np.allclose(seg.confidence, float(p[clutter].sum()), atol=1e-5)
    assert float(p[clutter].sum()) > float(p[VOC_CHAIR]) > float(p[1])


def test_segmentation_has_image_size_dtypes_and_unit_confidence(small_ckpt: Path) -> None:
    seg = Segmenter(SegmentationConfig(weights=str(small_ckpt))).segment(_image(121, 163))
    assert isinstance(seg, Segmentation)
    assert seg.labels.shape == seg.confidence.shape == (121, 163)
    assert seg.labels.dtype == np.uint8 and seg.confidence.dtype == np.float32
    assert seg.labels.max() < 11
    assert seg.confidence.min() >= 0.0 and seg.confidence.max() <= 1.0


def test_batch_equals_single_images_and_mixes_sizes(small_ckpt: Path) -> None:
    seg = Segmenter(SegmentationConfig(weights=str(small_ckpt), batch_size=2))
    images = [_image(seed=i) for i in range(3)] + [_image(90, 70, seed=9)]
    batch = seg.segment_batch(images)
    for image, got in zip(images, batch, strict=True):
        single = seg.segment(image)
        assert np.mean(single.labels == got.labels) > 0.999
        assert np.allclose(single.confidence, got.confidence, atol=1e-4)


def test_structural_labels_can_be_reported_as_background(tmp_path: Path) -> None:
    ckpt = random_checkpoint("deeplabv3plus_lite_mobilenet_v3_small")
    ckpt.state_dict["classifier.weight"].zero_()
    ckpt.state_dict["classifier.bias"].copy_(torch.tensor([0, 0, 0, 5.0, 0, 0, 0, 0, 0, 0, 0]))
    path = save_checkpoint(ckpt, tmp_path / "wall.safetensors")
    assert (Segmenter(SegmentationConfig(weights=str(path))).segment(_image()).labels == 3).all()
    cfg = SegmentationConfig(weights=str(path), structural_to_background=True)
    assert (Segmenter(cfg).segment(_image()).labels == 0).all()


def test_onnxruntime_agrees_with_torch(small_ckpt: Path) -> None:
    image = _image(96, 128, seed=4)
    eager = Segmenter(SegmentationConfig(weights=str(small_ckpt), channels_last=False)).segment(
        image
    )
    fast = Segmenter(SegmentationConfig(weights=str(small_ckpt), channels_last=True)).segment(image)
    onnx = Segmenter(SegmentationConfig(weights=str(small_ckpt), backend="onnx")).segment(image)
    assert len(np.unique(eager.labels)) > 2  # a decisive, non-constant map to compare
    for other in (fast, onnx):
        assert np.mean(other.labels == eager.labels) > 0.995
        assert np.abs(other.confidence - eager.confidence).max() < 1e-3


def test_bad_inputs_and_settings_are_one_line_errors(small_ckpt: Path, tmp_path: Path) -> None:
    seg = Segmenter(SegmentationConfig(weights=str(small_ckpt)))
    with pytest.raises(StageError, match="uint8 RGB"):
        seg.segment(np.zeros((10, 10), np.uint8))
    with pytest.raises(ConfigError, match="backend"):
        SegmentationConfig(backend="tensorrt")
    with pytest.raises(ConfigError, match="batch_size"):
        SegmentationConfig(batch_size=0)
    with pytest.raises(ModelError, match=r"needs a \.tflite"):
        Segmenter(SegmentationConfig(weights=str(small_ckpt), backend="tflite"))
    if not torch.cuda.is_available():
        with pytest.raises(ModelError, match="no CUDA"):
            Segmenter(SegmentationConfig(weights=str(small_ckpt)), device="cuda")


@pytest.mark.gpu
def test_cuda_matches_cpu(small_ckpt: Path) -> None:
    image = _image()
    cpu = Segmenter(SegmentationConfig(weights=str(small_ckpt)), device="cpu").segment(image)
    gpu = Segmenter(SegmentationConfig(weights=str(small_ckpt)), device="cuda").segment(image)
    assert np.mean(cpu.labels == gpu.labels) > 0.99


@pytest.mark.parametrize("model", TFLITE_MODELS)
def test_tflite_voc_model_segments_the_dog_photo(shared_data: Path, model: str) -> None:
    folder = shared_data / "deeplab_voc_tflite"
    cfg = SegmentationConfig(backend="tflite", weights=str(folder / model), threads=2)
    image = _read_rgb(folder / "dog_segmentation_256.bmp")
    # Oxford-IIIT Pet trimap, 0-based: 0 pet, 1 background, 2 uncertain border (not evaluated).
    trimap = cv2.imread(str(folder / "dog_segmentation_mask_256.bmp"), cv2.IMREAD_GRAYSCALE)
    seg = Segmenter(cfg).segment(image)
    gt = np.where(trimap == 2, 255, np.where(trimap == 0, VOC_TO_LABEL[VOC_DOG], 0))
    ious = confusion_iou(confusion_matrix(seg.labels, gt), classes=range(11))
    assert ious[10] > 0.9  # the dog (VOC 12 -> clutter)
    assert ious[0] > 0.85
    assert 0.5 < float(seg.confidence.mean()) <= 1.0


# The bird's outline in bird.bmp (512x343), traced by hand: beak, crown, back, tail, feet, chest.
BIRD_OUTLINE = [
    (37, 107), (60, 92), (90, 80), (125, 85), (160, 110), (230, 125), (290, 150), (330, 178),
    (400, 185), (460, 197), (485, 213), (470, 222), (400, 215), (320, 210), (280, 212), (265, 235),
    (240, 255), (200, 265), (185, 290), (150, 290), (125, 300), (150, 272), (120, 245), (92, 212),
    (78, 175), (70, 140), (58, 117),
]  # fmt: skip


@pytest.mark.parametrize("model", TFLITE_MODELS)
def test_tflite_voc_model_segments_the_bird_photo(shared_data: Path, model: str) -> None:
    # bird_segmentation_mask.bmp belongs to another photo (Coral's 513x513 bird_segmentation.bmp),
    # not to bird.bmp, so the ground truth here is the hand-traced outline above.
    folder = shared_data / "deeplab_voc_tflite"
    cfg = SegmentationConfig(backend="tflite", weights=str(folder / model), threads=2)
    image = _read_rgb(folder / "bird.bmp")
    seg = Segmenter(cfg).segment(image)
    gt = np.zeros(seg.labels.shape, np.uint8)
    cv2.fillPoly(gt, [np.array(BIRD_OUTLINE, np.int32)], VOC_TO_LABEL[VOC_BIRD])
    ious = confusion_iou(confusion_matrix(seg.labels, gt), classes=range(11))
    assert ious[10] > 0.7  # the bird (VOC 3 -> clutter)
    assert set(np.unique(seg.labels)) <= {0, 10}


def test_shipped_checkpoint_segments_an_unseen_simulated_room(sim_recording: Path) -> None:
    # The sim_recording fixture is seed 3: not among the training (100-219) or validation rooms.
    seg = Segmenter(SegmentationConfig())
    conf = np.zeros((11, 11), np.int64)
    with RecordingReader(sim_recording) as rec:
        for frame in rec.frames():
            if (
                frame.index % 10 == 0
                and frame.ground_truth
                and frame.ground_truth.labels is not None
            ):
                conf += confusion_matrix(seg.segment(frame.color).labels, frame.ground_truth.labels)
    assert conf.sum() == 3 * 640 * 480
    assert confusion_miou(conf) > 0.7
    assert np.trace(conf) / conf.sum() > 0.9


def test_importing_the_package_does_not_import_torch() -> None:
    code = (
        "import sys, process.segmentation as s; "
        "s.SegmentationConfig(); print('torch' in sys.modules)"
    )
    root = Path(__file__).resolve().parents[3]
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=root, check=True
    )
    assert out.stdout.strip() == "False"


def test_process_run_leaves_one_core_to_the_odometry(monkeypatch: pytest.MonkeyPatch) -> None:
    from process.segmentation.config import beside_odometry_threads

    for cores, threads in ((16, 15), (2, 1), (1, 1), (None, 1)):
        monkeypatch.setattr("os.cpu_count", lambda c=cores: c)
        assert beside_odometry_threads() == threads
