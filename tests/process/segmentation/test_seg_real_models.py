"""The real-image networks shipped in samples/: label table, TFLite runtime, combination, choice."""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from capture.recording import NUM_LABELS, VOC_TO_LABEL, RecordingReader
from process.errors import ConfigError, ModelError
from process.evaluate import confusion_iou, confusion_matrix
from process.segmentation import SegmentationConfig, Segmenter, ade20k
from process.segmentation.models import (
    ADE20K_TFLITE,
    SAMPLES,
    VOC_TFLITE,
    choose_model,
    is_simulated,
    shipped,
)
from process.segmentation.tflite_graph import cut_graph, logits_end
from process.segmentation.tflite_runtime import TfliteRuntime, label_map_for
from process.segmentation.weights import SAMPLES_CHECKPOINT

pytest.importorskip("ai_edge_litert", reason="the tflite extra (ai-edge-litert) is not installed")


# -- the ADE20K label table ------------------------------------------------------------------
def test_every_ade20k_class_is_mapped_by_its_name() -> None:
    shipped_words = [
        line.split("\t")[1].strip()
        for line in (SAMPLES / "deeplabv3_mnv2_ade20k_labels.txt").read_text().splitlines()
    ]
    assert len(ade20k.ADE20K_NAMES) == len(shipped_words) == 150
    # The model's labels.txt keeps the first word of each objectInfo150 name.
    assert [n.split()[0] for n in ade20k.ADE20K_NAMES] == shipped_words
    assert set(ade20k.ADE20K_TO_LABEL) == set(ade20k.ADE20K_NAMES)
    named = [n for names in ade20k._BY_LABEL.values() for n in names]
    assert sorted(set(named) - set(ade20k.ADE20K_NAMES)) == []  # no typo falls to clutter
    assert len(named) == len(set(named))  # no name under two labels
    assert len(ade20k.ADE20K_CLASS_TO_LABEL) == 151 and ade20k.ADE20K_CLASS_TO_LABEL[0] == 0
    assert all(0 <= v < NUM_LABELS for v in ade20k.ADE20K_CLASS_TO_LABEL)


@pytest.mark.parametrize(
    ("name", "label"),
    [
        ("wall", 3), ("floor", 2), ("ceiling", 1), ("table", 4), ("desk", 4), ("chair", 5),
        ("armchair", 5), ("swivel chair", 5), ("person", 6), ("plant", 7), ("sofa", 8),
        ("screen", 9), ("monitor", 9), ("crt screen", 9), ("computer", 9), ("bottle", 10),
        ("cabinet", 10), ("bed", 10), ("sky", 0), ("rug", 2), ("windowpane", 3), ("lamp", 10),
    ],
)  # fmt: skip
def test_ade20k_spot_checks(name: str, label: int) -> None:
    assert ade20k.ADE20K_TO_LABEL[name] == label
    index = ade20k.ADE20K_NAMES.index(name) + 1  # output 0 is "other"
    assert ade20k.ADE20K_CLASS_TO_LABEL[index] == label


# -- the TFLite runtime ----------------------------------------------------------------------
def test_label_maps_follow_the_class_count(tmp_path: Path) -> None:
    assert label_map_for(21, tmp_path) == VOC_TO_LABEL
    assert label_map_for(151, tmp_path) == ade20k.ADE20K_CLASS_TO_LABEL
    with pytest.raises(ModelError, match=r"has 7 classes; expected one of 21 .*151"):
        label_map_for(7, tmp_path)


def test_a_tflite_model_of_any_class_count_takes_its_map_from_the_config(tmp_path: Path) -> None:
    """segmentation.class_to_label maps a model's classes when its class count is not known."""
    with pytest.raises(ModelError, match=r"segmentation\.class_to_label in --config"):
        label_map_for(19, tmp_path)  # e.g. a Cityscapes model: not 21 or 151 classes
    image = np.random.default_rng(2).integers(0, 255, (96, 128, 3), dtype=np.uint8)
    walls = (0, *([3] * 150))  # every ADE20K class read as wall: the config's map is used
    cfg = SegmentationConfig(weights=str(ADE20K_TFLITE), class_to_label=walls, threads=1)
    seg = Segmenter(cfg).segment(image)
    assert set(np.unique(seg.labels)) <= {0, 3} and np.mean(seg.labels == 3) > 0.9
    short = SegmentationConfig(weights=str(ADE20K_TFLITE), class_to_label=(3, 4), threads=1)
    with pytest.raises(ModelError, match="151 classes but the label map has 2"):
        Segmenter(short)
    with pytest.raises(ModelError, match=r"class_to_label is for \.tflite models"):
        Segmenter(SegmentationConfig(class_to_label=walls))  # the simulator checkpoint
    with pytest.raises(ConfigError, match="one label 0-10 per model class"):
        SegmentationConfig(class_to_label=(0, 11))
    from process.config import load_config

    toml = tmp_path / "c.toml"
    toml.write_text("[segmentation]\nbackend = 'tflite'\nclass_to_label = [0, 2, 3, 10]\n")
    assert load_config(toml).segmentation.class_to_label == (0, 2, 3, 10)
    toml.write_text("[segmentation]\nclass_to_label = ['wall']\n")
    with pytest.raises(ConfigError, match="one label 0-10 per model class"):
        load_config(toml)


def test_float_ade20k_and_int8_voc_models_load_with_their_class_counts() -> None:
    ade = TfliteRuntime(ADE20K_TFLITE, threads=1)
    voc = TfliteRuntime(VOC_TFLITE, threads=1)
    assert (ade.n_classes, voc.n_classes) == (151, 21)
    assert ade.fixed_input_size == voc.fixed_input_size == (513, 513)
    image = np.random.default_rng(0).integers(0, 255, (1, 513, 513, 3), dtype=np.uint8)
    for runtime in (ade, voc):
        probs = runtime(image)
        assert probs.shape == (1, NUM_LABELS, 129, 129)
        assert torch.allclose(probs.sum(dim=1), torch.ones(1, 129, 129), atol=1e-4)
    assert float(voc(image)[:, 1:4].max()) == 0.0  # VOC never says ceiling, floor or wall
    with pytest.raises(ModelError, match="151 classes but the label map has 21"):
        TfliteRuntime(ADE20K_TFLITE, class_to_label=VOC_TO_LABEL)


def test_cut_graphs_label_every_pixel_as_the_published_models_do() -> None:
    """The logits cut off before the trailing resize/ArgMax give the whole model's argmax."""
    from ai_edge_litert.interpreter import Interpreter

    image = np.random.default_rng(1).integers(0, 255, (1, 513, 513, 3), dtype=np.uint8)
    image[:, 100:400, 150:350] = (200, 40, 40)  # a block, so that not every pixel is noise
    for path in (ADE20K_TFLITE, VOC_TFLITE):
        whole = Interpreter(model_path=str(path), num_threads=1)
        whole.allocate_tensors()
        inp = whole.get_input_details()[0]
        x = image if inp["dtype"] == np.uint8 else image.astype(np.float32) / 127.5 - 1.0
        whole.set_tensor(inp["index"], x)
        whole.invoke()
        out = whole.get_tensor(whole.get_output_details()[0]["index"])
        expected = out.argmax(-1) if out.ndim == 4 else out  # ADE20K: scores, VOC: ArgMax
        cut = TfliteRuntime(path, threads=1).interp  # its output: the class scores
        cut.set_tensor(inp["index"], x)
        cut.invoke()
        logits = torch.from_numpy(cut.get_tensor(cut.get_output_details()[0]["index"]) * 1.0)
        # class scores, resized to 513 corner-aligned as DeepLab does, argmax-ed
        up = torch.nn.functional.interpolate(
            logits.permute(0, 3, 1, 2), size=(513, 513), mode="bilinear", align_corners=True
        )
        assert (up.argmax(1).numpy() == expected).mean() > 0.995


def test_a_graph_that_cannot_be_cut_is_refused_in_one_line() -> None:
    model = ADE20K_TFLITE.read_bytes()
    with pytest.raises(ValueError, match="cannot keep 0 operators"):
        cut_graph(model, output_tensor=0, n_operators=0)
    ops: list[dict[str, object]] = [{"op_name": "CONV_2D", "inputs": [1], "outputs": [2]}]
    assert logits_end(ops, 2) == (2, 1)  # nothing to cut
    ops += [{"op_name": "RESIZE_BILINEAR", "inputs": [2, 7], "outputs": [3]}]
    ops += [{"op_name": "ARG_MAX", "inputs": [3, 8], "outputs": [4]}]
    assert logits_end(ops, 4) == (2, 1)


def test_ade20k_finds_the_structure_of_a_simulated_room(sim_recording: Path) -> None:
    seg = Segmenter(SegmentationConfig(model="ade20k", threads=2))
    with RecordingReader(sim_recording) as rec:
        frame = next(iter(rec.frames()))
    assert frame.ground_truth is not None and frame.ground_truth.labels is not None
    gt = frame.ground_truth.labels
    labels = seg.segment(frame.color).labels
    iou = confusion_iou(confusion_matrix(labels, gt))
    assert iou.get(3, 0.0) > 0.5  # the walls (0.67 over 12 unseen frames, benchmarks.seg_models)
    structural = np.isin(gt, (1, 2, 3))
    assert np.mean(np.isin(labels[structural], (1, 2, 3))) > 0.7


# -- the combined backend (its rule: test_seg_combined.py) ----------------------------------
def test_combined_backend_segments_and_can_drop_structure(sim_recording: Path) -> None:
    with RecordingReader(sim_recording) as rec:
        color = next(iter(rec.frames())).color
    seg = Segmenter(SegmentationConfig(backend="combined", threads=2)).segment(color)
    assert seg.labels.shape == color.shape[:2] and seg.labels.dtype == np.uint8
    assert float(seg.confidence.min()) >= 0.0 and float(seg.confidence.max()) <= 1.0
    assert np.isin(seg.labels, (1, 2, 3)).mean() > 0.3
    cfg = SegmentationConfig(model="combined", threads=2, structural_to_background=True)
    no_structure = Segmenter(cfg).segment(color)
    assert not np.isin(no_structure.labels, (1, 2, 3)).any()
    with pytest.raises(ModelError, match="combined backend runs the two networks"):
        Segmenter(SegmentationConfig(backend="combined", weights=str(SAMPLES_CHECKPOINT)))


# -- which model a run uses ------------------------------------------------------------------
def test_simulated_recordings_get_the_simulator_checkpoint() -> None:
    assert is_simulated("Simulated Intel RealSense D435") and not is_simulated(
        "Intel RealSense D435"
    )
    choice = choose_model(SegmentationConfig(), device_name="Simulated Intel RealSense D435")
    assert (choice.name, choice.path, choice.backend) == ("simulator", SAMPLES_CHECKPOINT, "torch")
    assert "simulated recording" in choice.reason


@pytest.mark.parametrize("device", ["Intel RealSense D435", "tum_fr1_rpy", None])
def test_real_recordings_get_the_real_image_networks(device: str | None) -> None:
    choice = choose_model(SegmentationConfig(), device_name=device)
    assert (choice.name, choice.backend) == ("combined", "combined")
    assert "real recording" in choice.reason


def test_weights_then_config_win_over_the_device(tmp_path: Path) -> None:
    real, sim = "Intel RealSense D435", "Simulated Intel RealSense D435"
    ckpt = tmp_path / "mine.safetensors"
    choice = choose_model(SegmentationConfig(model="voc"), weights=ckpt, device_name=real)
    assert (choice.name, choice.path, choice.backend) == ("mine.safetensors", ckpt, "torch")
    assert choice.reason == "--weights was given"
    tfl = choose_model(SegmentationConfig(weights=str(VOC_TFLITE)), device_name=sim)
    assert (tfl.path, tfl.backend) == (
        VOC_TFLITE,
        "tflite",
    ) and "segmentation.weights" in tfl.reason
    ade = choose_model(SegmentationConfig(model="ade20k"), device_name=sim)
    assert (ade.name, ade.path, ade.backend) == ("ade20k", ADE20K_TFLITE, "tflite")
    onnx = choose_model(SegmentationConfig(backend="onnx"), device_name=real)
    assert (onnx.name, onnx.backend) == ("simulator", "onnx")
    assert shipped("simulator", "x").path == SAMPLES_CHECKPOINT
    with pytest.raises(ConfigError, match=r"segmentation\.model must be one of"):
        SegmentationConfig(model="deeplab")


def test_a_run_says_which_model_ran_and_why(recording: Path, tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from process import outputs
    from process.cli import app

    def run(*extra: str) -> dict[str, object]:
        out = tmp_path / f"out{len(extra)}"
        args = ["run", str(recording), "--out", str(out), "--stages", "segmentation", "--no-viz"]
        result = CliRunner().invoke(app, [*args, *extra])
        assert result.exit_code == 0, result.output
        seg: dict[str, object] = json.loads((out / outputs.METRICS).read_text())["segmentation"]
        return seg

    real = run()  # the fixture's device is "synthetic": not the simulator, so a real camera
    assert real["model"] == "combined" and "real recording" in str(real["model_reason"])
    assert isinstance(real["load_s"], float) and real["load_s"] > 0
    mine = run("--weights", str(SAMPLES_CHECKPOINT))
    assert (
        mine["model"] == SAMPLES_CHECKPOINT.name and mine["model_reason"] == "--weights was given"
    )
    assert isinstance(real["threads"], int) and real["threads"] >= 1
    # The summary table printed at the end of the run says which model ran and why, too.
    from rich.console import Console

    console = Console(width=400, record=True, file=io.StringIO())
    console.print(outputs.summary_table({"segmentation": real}))
    text = console.export_text()
    assert "model_reason" in text and str(real["model_reason"]) in text
    assert f"threads {real['threads']}" in " ".join(text.replace("│", " ").split())
