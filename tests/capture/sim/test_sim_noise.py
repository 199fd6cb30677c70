"""The D435 depth model: Intel's RMS formula, range, stereo shadows, edges, dark and glossy."""

from __future__ import annotations

import numpy as np
import pytest

from capture.errors import CaptureError
from capture.sim.noise import ColorSensorNoise, D435DepthModel, depth_edges, stereo_occlusion
from capture.sim.render import DepthView

FOCAL_PX = 385.0


def flat_view(
    depth_m: float,
    *,
    shape: tuple[int, int] = (400, 500),
    luminance: float = 0.5,
    glossy: bool = False,
    cos: float = 0.9,
) -> DepthView:
    return DepthView(
        np.full(shape, depth_m, np.float32),
        np.full(shape, cos, np.float32),
        np.full(shape, luminance, np.float32),
        np.full(shape, glossy),
    )


@pytest.mark.parametrize("depth_m", [1.0, 3.0])
def test_noise_spread_matches_intel_rms_formula(depth_m: float) -> None:
    model = D435DepthModel()
    expected = depth_m**2 * 0.08 / (FOCAL_PX * 0.050)  # 4.2 mm at 1 m, 37 mm at 3 m
    assert model.rms_error_m(depth_m, focal_px=FOCAL_PX) == pytest.approx(expected)
    noisy = model.add_noise(
        flat_view(depth_m).depth_m, focal_px=FOCAL_PX, rng=np.random.default_rng(1)
    )
    # 200,000 samples: the standard deviation is known to ~0.2 %; first-order formula to ~1 %.
    assert float(np.std(noisy)) == pytest.approx(expected, rel=0.03)
    # Depth = f B / disparity is convex in the disparity: E[z'] = z (1 + (subpixel / disparity)^2).
    relative = 0.08 / (FOCAL_PX * 0.050 / depth_m)
    mean = depth_m * (1 + relative**2)
    assert float(np.mean(noisy)) == pytest.approx(mean, abs=4 * expected / np.sqrt(noisy.size))


def test_output_is_millimetres_with_unit_quantisation() -> None:
    model = D435DepthModel(subpixel=0.0, edge_jump=1.0)
    view = flat_view(1.2345, shape=(40, 60))
    depth_mm = model.apply(view, focal_px=FOCAL_PX, rng=np.random.default_rng(0))
    assert depth_mm.dtype == np.uint16
    valid = depth_mm[:, 20:]  # left of column fB/z = 16 the right imager sees nothing (left band)
    assert np.all(valid == 1234) or np.all(valid == 1235)


@pytest.mark.parametrize(
    ("depth_m", "valid"), [(0.2, False), (0.5, True), (9.5, True), (10.5, False)]
)
def test_depth_outside_the_range_is_invalid(depth_m: float, valid: bool) -> None:
    model = D435DepthModel()
    depth_mm = model.apply(
        flat_view(depth_m, shape=(20, 200)), focal_px=FOCAL_PX, rng=np.random.default_rng(0)
    )
    assert bool(np.any(depth_mm[:, -20:] > 0)) is valid


def test_stereo_shadow_left_of_a_foreground_object_and_left_band() -> None:
    depth = np.full((10, 300), 3.0, np.float32)
    depth[:, 150:200] = 1.0  # a pole at 1 m in front of a wall at 3 m
    hidden = stereo_occlusion(depth, focal_px=FOCAL_PX, baseline_m=0.05)
    band = FOCAL_PX * 0.05 / 3.0  # the left band: columns that land left of the right image
    shadow = FOCAL_PX * 0.05 * (1 / 1.0 - 1 / 3.0)  # wall columns hidden behind the pole
    row = hidden[5]
    assert np.flatnonzero(~row)[0] == int(np.ceil(band))
    shadow_columns = np.flatnonzero(row[:150])
    shadow_columns = shadow_columns[shadow_columns > band + 1]
    assert len(shadow_columns) == pytest.approx(shadow, abs=1.0)
    assert shadow_columns.max() == 149
    assert not row[150:].any()  # the pole and the wall right of it are seen by both imagers


def test_depth_edges_are_invalidated() -> None:
    depth = np.full((20, 20), 2.0, np.float32)
    depth[:, 10:] = 1.0
    edges = depth_edges(depth, relative_jump=0.05)
    assert set(np.flatnonzero(edges[10])) == {9, 10}


def test_dark_surfaces_lose_about_half_their_pixels() -> None:
    model = D435DepthModel()
    dark = model.invalid_mask(
        flat_view(1.0, luminance=0.05), focal_px=FOCAL_PX, rng=np.random.default_rng(2)
    )
    bright = model.invalid_mask(
        flat_view(1.0, luminance=0.6), focal_px=FOCAL_PX, rng=np.random.default_rng(2)
    )
    cols = slice(30, None)  # past the left band
    assert dark[:, cols].mean() == pytest.approx(0.5, abs=0.01)
    assert not bright[:, cols].any()


@pytest.mark.parametrize(
    ("glossy", "cos", "invalid"),
    [(True, 0.999, True), (True, 0.9, False), (False, 0.999, False), (False, 0.05, True)],
)
def test_specular_and_grazing_surfaces_are_invalid(glossy: bool, cos: float, invalid: bool) -> None:
    model = D435DepthModel()
    mask = model.invalid_mask(
        flat_view(1.0, glossy=glossy, cos=cos), focal_px=FOCAL_PX, rng=np.random.default_rng(0)
    )
    assert bool(mask[:, 30:].all()) is invalid
    assert bool(mask[:, 30:].any()) is invalid


def test_bad_model_parameters_are_rejected() -> None:
    with pytest.raises(CaptureError, match="min_depth_m"):
        D435DepthModel(min_depth_m=2.0, max_depth_m=1.0)


def test_color_noise_has_its_sigma_and_keeps_the_range() -> None:
    noise = ColorSensorNoise(np.random.default_rng(0), size=120 * 160 * 3, sigma=2.0)
    image = np.full((120, 160, 3), 128, np.uint8)
    out = noise.apply(image)
    assert float(np.std(out.astype(np.float64))) == pytest.approx(2.0, rel=0.05)
    assert noise.apply(np.full((120, 160, 3), 255, np.uint8)).max() == 255
