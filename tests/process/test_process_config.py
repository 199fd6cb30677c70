from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from process.config import ReplayConfig, load_config, resolve_stages, to_toml
from process.errors import ConfigError


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "c.toml"
    path.write_text(text)
    return path


def test_no_file_gives_the_defaults() -> None:
    assert load_config(None) == ReplayConfig()


def test_a_file_overrides_only_what_it_names(tmp_path: Path) -> None:
    cfg = load_config(write(tmp_path, "[fusion]\nvoxel_size_m = 0.05\n[refine]\nk_max = 12\n"))
    assert cfg.fusion.voxel_size_m == 0.05
    assert cfg.refine.k_max == 12
    assert cfg.odometry == ReplayConfig().odometry


def test_an_int_is_accepted_where_a_float_is_expected(tmp_path: Path) -> None:
    cfg = load_config(write(tmp_path, "[fusion]\nmax_depth_m = 3\n"))
    assert cfg.fusion.max_depth_m == 3.0
    assert isinstance(cfg.fusion.max_depth_m, float)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("[fusion]\nvoxel_size = 0.05\n", r"unknown key\(s\) \['voxel_size'\] in \[fusion\]"),
        ("[fusoin]\nvoxel_size_m = 0.05\n", r"unknown key\(s\) \['fusoin'\] in top level"),
        ("[fusion]\nvoxel_size_m = 'big'\n", "'fusion.voxel_size_m' must be float"),
        ("[refine]\nregrowth = 1\n", "'refine.regrowth' must be bool"),
        ("fusion = 3\n", "must be a table"),
        ("[fusion\n", "not valid TOML"),
    ],
)
def test_bad_files_are_rejected_by_name(tmp_path: Path, text: str, match: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(ConfigError, match=match) as err:
        load_config(path)
    assert "\n" not in str(err.value)
    assert str(err.value).endswith(str(path))


def test_a_value_out_of_range_is_rejected(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="voxel_size_m"):
        load_config(write(tmp_path, "[fusion]\nvoxel_size_m = -1.0\n"))


def test_a_missing_file_is_one_line(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="config file not found"):
        load_config(tmp_path / "absent.toml")


def test_the_effective_config_reads_back_equal(tmp_path: Path) -> None:
    cfg = load_config(
        write(tmp_path, "[odometry]\nn_features = 500\n[refine]\ndbscan_method = 1\n")
    )
    text = to_toml(cfg)
    tomllib.loads(text)  # valid TOML
    assert load_config(write(tmp_path, text)) == cfg


def test_the_sample_config_shows_the_defaults_it_sets() -> None:
    # samples/sample.toml documents knobs at their current defaults: a default changed in the
    # code without the sample (or the reverse) fails here.
    sample = Path(__file__).resolve().parents[2] / "samples" / "sample.toml"
    text = sample.read_text(encoding="utf-8")
    assert sum(1 for line in text.splitlines() if "=" in line and not line.startswith("#")) >= 10
    assert load_config(sample) == ReplayConfig()


@pytest.mark.parametrize(
    ("spec", "stages"),
    [
        ("odometry", ("odometry",)),
        ("segmentation", ("odometry", "segmentation")),
        ("refinement", ("odometry", "segmentation", "fusion", "refinement")),
        ("odometry,fusion", ("odometry", "segmentation", "fusion")),
    ],
)
def test_later_stages_imply_earlier_ones(spec: str, stages: tuple[str, ...]) -> None:
    assert resolve_stages(spec) == stages


def test_an_unknown_stage_lists_the_valid_ones() -> None:
    with pytest.raises(ConfigError, match="valid stages, in order: odometry, segmentation"):
        resolve_stages("odometry,slam")


def test_viz_full_fidelity_options_reach_the_logger(tmp_path: Path) -> None:
    cfg = load_config(write(tmp_path, "[viz]\ncompress = false\ndepth_every_n = 1\n"))
    assert cfg.viz.logger_options() == {"compress": False, "jpeg_quality": 70, "depth_every_n": 1}


@pytest.mark.parametrize(
    ("text", "match"),
    [("jpeg_quality = 0", "viz.jpeg_quality"), ("depth_every_n = 0", "viz.depth_every_n")],
)
def test_viz_options_out_of_range_are_one_line_errors(
    tmp_path: Path, text: str, match: str
) -> None:
    with pytest.raises(ConfigError, match=match) as info:
        load_config(write(tmp_path, f"[viz]\n{text}\n"))
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    ("text", "match"),
    [("max_lag_s = -1.0", "follow.max_lag_s"), ("min_tracked_hz = 0.0", "follow.min_tracked_hz")],
)
def test_follow_options_out_of_range_are_one_line_errors(
    tmp_path: Path, text: str, match: str
) -> None:
    with pytest.raises(ConfigError, match=match) as info:
        load_config(write(tmp_path, f"[follow]\n{text}\n"))
    assert "\n" not in str(info.value)
