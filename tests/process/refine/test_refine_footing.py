"""What regrowth gave a screen or clutter on the level surface it stands on goes back."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from helpers_refine import UP, grid_patch, labelled

from capture.recording import Label
from process.refine import RefineConfig, refine
from process.refine.footing import beyond_feet
from process.refine.job import refinement_metrics

SCREEN, CLUTTER, CHAIR, FLOOR = Label.TV_MONITOR, Label.CLUTTER, Label.CHAIR, Label.FLOOR
Points = npt.NDArray[np.float32]


def _upright(y: tuple[float, float], z: tuple[float, float], x: float = 0.0) -> Points:
    """An upright grid facing x at `x`, 1 cm spacing."""
    face = grid_patch(y, z, step=0.01)[:, [2, 0, 1]]
    return (face + np.array([x, 0.0, 0.0], np.float32)).astype(np.float32)


def test_growth_along_the_surface_under_a_screen_beyond_its_foot_goes_back() -> None:
    """A screen (cluster 1) stands on a cabinet's top 50 cm up: its own points a panel from 56
    cm up, its stand and its base plate on the top (10 cm square). Regrowth gave it the top all
    round, the panel's upright lower edge (52-56 cm, in the foot's 3 cm band at 52-53 cm), its
    level upper face, and a shelf 20 cm over the top behind it. Given back: the top beyond the
    foot's cells grown by two cells; kept: the top by the foot, the upright edge, the upper face
    and the shelf (level, but over the foot's band). A chair's growth on the floor (cluster 2)
    is kept: a chair stands on legs. A cup's over the desk it stands on (cluster 3, clutter)
    goes back beyond its foot."""
    top = grid_patch((-0.2, 0.2), (-0.6, 0.6), z=0.5, step=0.02)
    panel = _upright((-0.45, 0.45), (0.56, 0.8))
    stand = np.concatenate(
        [
            _upright((-0.03, 0.03), (0.5, 0.56), x=0.03),
            grid_patch((-0.02, 0.08), (-0.05, 0.05), z=0.5, step=0.01),
        ]
    )
    edge = _upright((-0.45, 0.45), (0.52, 0.56))  # the panel's lower edge, missed
    upper = grid_patch((-0.01, 0.03), (-0.45, 0.45), z=0.8, step=0.01)  # level, high
    shelf = grid_patch((0.15, 0.3), (-0.3, 0.3), z=0.7, step=0.02)  # level, over the band
    chair_own = grid_patch((2.0, 2.4), (2.0, 2.4), z=0.45)
    chair_floor = grid_patch((1.8, 2.6), (1.8, 2.6), z=0.0, step=0.05)
    cup_own = _upright((3.0, 3.08), (0.76, 0.86), x=3.0)
    desk = grid_patch((2.8, 3.2), (2.8, 3.3), z=0.75, step=0.02)
    parts = [panel, stand, top, edge, upper, shelf, chair_own, chair_floor, cup_own, desk]
    points = np.concatenate(parts).astype(np.float32)
    sizes = [len(p) for p in parts]
    labels = np.repeat(np.array([SCREEN] * 6 + [CHAIR] * 2 + [CLUTTER] * 2, np.uint8), sizes)
    clusters = np.repeat(np.array([1] * 6 + [2, 2, 3, 3], np.int32), sizes)
    part = np.repeat(np.arange(len(parts)), sizes)
    grown = np.flatnonzero(~np.isin(part, [0, 1, 6, 8]))
    back = beyond_feet(points, labels, clusters, grown, UP)
    on_top = np.flatnonzero(part == 2)
    # the foot's cells (5 cm, on a grid) grown by two cells reach 10-15 cm past it
    x, y = points[on_top, 0] - 0.03, np.abs(points[on_top, 1])
    clear = np.abs(points[on_top, 0]) > 0.1  # by the upright edge, its neighbours are not level
    assert np.isin(on_top[((np.abs(x) > 0.2) | (y > 0.2)) & clear], back).all()
    assert not np.isin(on_top[(np.abs(x) < 0.04) & (y < 0.09)], back).any()  # by the plate
    assert not np.isin(np.flatnonzero(np.isin(part, [3, 4, 5, 7])), back).any()
    on_desk = np.flatnonzero(part == 9)
    far = on_desk[np.hypot(points[on_desk, 0] - 3.0, points[on_desk, 1] - 3.04) > 0.25]
    assert np.isin(far, back).all()
    assert np.isin(back, np.concatenate([on_top, on_desk])).all()
    assert len(beyond_feet(points, labels, clusters, np.zeros(0, np.intp), UP)) == 0


def _cabinet_with_screen() -> tuple[Points, npt.NDArray[np.uint8], npt.NDArray[np.intp]]:
    """A 4 x 4 m floor, a cabinet 50 cm tall (1.4 x 0.5 m, top and front; no class, so the
    network leaves it unlabelled) and on it a screen 1.1 m wide whose panel the network
    labels from 52 cm up."""
    floor = grid_patch((-2.0, 2.0), (-2.0, 2.0), step=0.02)
    top = grid_patch((-0.25, 0.25), (-0.7, 0.7), z=0.5, step=0.01)
    front = _upright((-0.7, 0.7), (0.02, 0.49), x=-0.25)
    panel = _upright((-0.55, 0.55), (0.52, 1.15), x=0.02)
    back = _upright((-0.55, 0.55), (0.52, 1.15), x=0.05)
    parts = [floor, top, front, panel, back]
    labels = np.repeat(np.array([FLOOR, 0, 0, SCREEN, SCREEN], np.uint8), [len(p) for p in parts])
    start = len(floor)
    return np.concatenate(parts), labels, np.arange(start, start + len(top))


def test_the_refinement_gives_a_cabinet_top_back_from_the_screen_on_it() -> None:
    """The whole refinement: regrowth grows the screen over the cabinet's unlabelled top; the
    rule gives back what lies beyond the screen's foot (counted in metrics.json, shown with the
    votes in the .rrd), so most of the top ends unlabelled, and the screen stays a screen.
    Without the rule (as in `paper()`) the screen keeps those points."""
    rng = np.random.default_rng(0)
    points, labels, on_top = _cabinet_with_screen()
    cloud = labelled(points + rng.normal(0.0, 0.002, points.shape).astype(np.float32), labels)
    result = refine(cloud, RefineConfig(), up=UP)
    beyond = on_top[np.abs(points[on_top, 0] - 0.035) > 0.2]
    assert len(result.beyond_feet) > 0 and np.isin(result.beyond_feet, on_top).all()
    assert (result.labels_iii[beyond] == 0).mean() > 0.9
    on_screen = np.flatnonzero(labels == SCREEN)
    assert (result.labels_iii[on_screen] == SCREEN).mean() > 0.95
    back = result.beyond_feet
    assert refinement_metrics(result, gt_cloud=None)["points"]["beyond_feet"] == len(back)
    shown = {tuple(p) for p in result.seam_cloud().points.tolist()}  # the .rrd's votes entity
    assert {tuple(p) for p in cloud.points[back].tolist()} <= shown
    off = refine(cloud, RefineConfig(beyond_feet=False), up=UP)
    assert (off.labels_iii[back] == SCREEN).all() and len(off.beyond_feet) == 0
    assert not RefineConfig.paper().beyond_feet
