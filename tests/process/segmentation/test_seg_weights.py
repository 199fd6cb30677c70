from __future__ import annotations

import pickle
import urllib.error
from pathlib import Path

import pytest
import torch
from helpers_seg import fake_torchvision_state, manifest, random_checkpoint

from capture.recording import VOC_TO_LABEL
from process.errors import ModelError
from process.segmentation.deeplab import build_model
from process.segmentation.weights import (
    build_from_checkpoint,
    init_from,
    load_checkpoint,
    parameter_count,
    resolve_weights,
    save_checkpoint,
    torchvision_file,
)

ARCH = "deeplabv3plus_lite_mobilenet_v3_small"


def _one_line(err: pytest.ExceptionInfo[ModelError], path: Path) -> None:
    text = str(err.value)
    assert "\n" not in text
    assert text.endswith(str(path))


@torch.no_grad()
@pytest.mark.parametrize("suffix", [".safetensors", ".pt"])
def test_checkpoint_round_trip_gives_identical_outputs(tmp_path: Path, suffix: str) -> None:
    ckpt = random_checkpoint(ARCH, seed=1)
    path = save_checkpoint(ckpt, tmp_path / f"model{suffix}")
    back = load_checkpoint(path)
    assert back.arch == ckpt.arch
    assert back.class_to_label == tuple(range(11))
    assert back.short_side_px == 96
    x = torch.rand(1, 3, 64, 80)
    assert torch.equal(build_from_checkpoint(ckpt)(x), build_from_checkpoint(back)(x))


@torch.no_grad()
def test_half_precision_checkpoint_is_half_the_size_and_close(tmp_path: Path) -> None:
    ckpt = random_checkpoint(ARCH, seed=1)
    full = save_checkpoint(ckpt, tmp_path / "full.safetensors")
    half = save_checkpoint(ckpt, tmp_path / "half.safetensors", half=True)
    assert half.stat().st_size < 0.55 * full.stat().st_size
    x = torch.rand(1, 3, 64, 80)
    a, b = build_from_checkpoint(ckpt)(x), build_from_checkpoint(load_checkpoint(half))(x)
    assert (a.argmax(1) == b.argmax(1)).float().mean() > 0.98


@pytest.mark.parametrize("suffix", [".safetensors", ".pt"])
def test_corrupt_checkpoint_is_a_one_line_model_error(tmp_path: Path, suffix: str) -> None:
    good = save_checkpoint(random_checkpoint(ARCH), tmp_path / f"good{suffix}")
    bad = tmp_path / f"bad{suffix}"
    bad.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    with pytest.raises(ModelError, match="corrupt") as err:
        load_checkpoint(bad)
    _one_line(err, bad)


@pytest.mark.filterwarnings("ignore:Detected pickle protocol")
def test_pickled_object_is_refused_not_executed(tmp_path: Path) -> None:
    path = tmp_path / "evil.pt"
    path.write_bytes(pickle.dumps({"state_dict": {"x": Path("/")}}))
    with pytest.raises(ModelError, match="cannot read") as err:
        load_checkpoint(path)
    _one_line(err, path)


def test_wrong_architecture_is_a_one_line_model_error(tmp_path: Path) -> None:
    ckpt = random_checkpoint(ARCH)
    other = random_checkpoint("deeplabv3plus_lite_mobilenet_v3_large")
    swapped = type(ckpt)(
        arch=other.arch, state_dict=ckpt.state_dict, class_to_label=ckpt.class_to_label
    )
    path = save_checkpoint(swapped, tmp_path / "swapped.safetensors")
    with pytest.raises(ModelError, match="does not fit architecture") as err:
        build_from_checkpoint(load_checkpoint(path))
    _one_line(err, path)


def test_foreign_state_dict_and_missing_file_are_model_errors(tmp_path: Path) -> None:
    path = tmp_path / "resnet.pt"
    torch.save({"conv1.weight": torch.zeros(2)}, path)
    with pytest.raises(ModelError, match="not a segmentation checkpoint") as err:
        load_checkpoint(path)
    _one_line(err, path)
    with pytest.raises(ModelError, match="not found"):
        resolve_weights(tmp_path / "absent.safetensors")


def test_manifests_match_torchvision_published_parameter_counts() -> None:
    for name in ("deeplabv3_mobilenet_v3_large", "mobilenet_v3_large"):
        m = manifest(name)
        keys = m["keys"]
        assert isinstance(keys, list)
        stats = ("running_mean", "running_var", "num_batches_tracked")
        n = sum(int(torch.Size(s).numel()) for k, s in keys if not k.endswith(stats))
        assert n == m["num_params_published"]


@torch.no_grad()
def test_torchvision_voc_checkpoint_loads_every_tensor(tmp_path: Path) -> None:
    state = fake_torchvision_state("deeplabv3_mobilenet_v3_large", seed=3)
    path = _save(tmp_path / "deeplabv3_mobilenet_v3_large-fc3c493d.pth", state)
    ckpt = load_checkpoint(path)
    assert ckpt.class_to_label == VOC_TO_LABEL
    model = build_from_checkpoint(ckpt)
    ours = model.state_dict()
    pairs = {"backbone.16.0.weight": "backbone.features.16.0.weight",
             "backbone.13.block.2.fc1.weight": "backbone.features.13.block.2.fc1.weight",
             "classifier.0.convs.4.1.weight": "aspp.convs.4.1.weight",
             "classifier.0.project.0.weight": "aspp.project.0.weight",
             "classifier.1.weight": "decoder.head.0.weight",
             "classifier.2.running_var": "decoder.head.1.running_var",
             "classifier.4.bias": "classifier.bias"}  # fmt: skip
    for theirs, mine in pairs.items():
        assert torch.equal(ours[mine], state[theirs])
    kept = [k for k in state if not k.startswith("aux_classifier.")]
    assert len(ours) == len(kept)
    assert sorted(float(v.sum()) for v in ours.values()) == sorted(
        float(state[k].sum()) for k in kept
    )
    assert model(torch.rand(1, 3, 65, 81)).shape == (1, 21, 65, 81)


def test_torchvision_checkpoint_without_batchnorm_counters_loads(tmp_path: Path) -> None:
    state = fake_torchvision_state("deeplabv3_mobilenet_v3_large")
    state = {k: v for k, v in state.items() if not k.endswith("num_batches_tracked")}
    model = build_from_checkpoint(load_checkpoint(_save(tmp_path / "old.pth", state)))
    assert torch.equal(model.state_dict()["classifier.weight"], state["classifier.4.weight"])


def test_imagenet_backbone_initialises_our_backbone_only(tmp_path: Path) -> None:
    state = fake_torchvision_state("mobilenet_v3_large", seed=5)
    path = _save(tmp_path / "mobilenet_v3_large-8738ca79.pth", state)
    model = build_model("deeplabv3plus_lite_mobilenet_v3_large")
    missing = init_from(model, path)
    assert not any(k.startswith("backbone.") for k in missing)
    assert any(k.startswith("decoder.") for k in missing)
    assert torch.equal(
        model.state_dict()["backbone.features.7.block.1.0.weight"],
        state["features.7.block.1.0.weight"],
    )
    with pytest.raises(ModelError, match="backbone without a segmentation head") as err:
        load_checkpoint(path)
    _one_line(err, path)


def test_voc_checkpoint_initialises_deeplabv3plus_backbone_and_aspp(tmp_path: Path) -> None:
    path = _save(tmp_path / "tv.pth", fake_torchvision_state("deeplabv3_mobilenet_v3_large"))
    model = build_model("deeplabv3plus_mobilenet_v3_large")
    missing = init_from(model, path)
    assert all(k.startswith(("decoder.", "classifier.")) for k in missing)
    assert parameter_count(model) > 0


def test_hub_download_offline_says_where_to_put_the_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(torch.hub, "get_dir", lambda: str(tmp_path / "hub"))

    def offline(url: str, dst: str, **kwargs: object) -> None:
        raise urllib.error.URLError("Temporary failure in name resolution")

    monkeypatch.setattr(torch.hub, "download_url_to_file", offline)
    dst = tmp_path / "hub" / "checkpoints" / "deeplabv3_mobilenet_v3_large-fc3c493d.pth"
    with pytest.raises(ModelError, match="offline") as err:
        resolve_weights("torchvision:deeplabv3_mobilenet_v3_large")
    _one_line(err, dst)
    dst.write_bytes(b"cached")
    assert torchvision_file("deeplabv3_mobilenet_v3_large") == dst


def _save(path: Path, state: dict[str, torch.Tensor]) -> Path:
    torch.save(state, path)
    return path
