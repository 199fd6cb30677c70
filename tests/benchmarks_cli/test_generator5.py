"""Generator 5: truth from the meshes, structure unlabelled, each image-space error as described."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import numpy.typing as npt
import pytest

from benchmarks.gen4_rooms import build_room
from benchmarks.gen5_net import REF_WIDTH, WRONG_CLASS, Gen5Errors, Network, View
from benchmarks.generator5 import Camera, Caster, Gen5Scene, gen5_scene, main, walk
from capture.recording import OBJECT_LABELS, Label
from process.evaluate import label_metrics

SMALL = Camera(views=10, width=212, height=120)
QUIET = replace(SMALL, noise_k=0.0, flying_rate=0.0)


def small(seed: int = 1, **kwargs: object) -> Gen5Scene:
    return gen5_scene(seed=seed, voxel_m=0.03, room="office", **kwargs)  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def scene() -> Gen5Scene:
    return small(camera=SMALL)


@pytest.fixture(scope="module")
def views() -> tuple[list[View], list[bool]]:
    """Eight full-size views of an office, with which parts are thin."""
    rng = np.random.default_rng(7)
    room = build_room("office", rng)
    caster = Caster(room.parts)
    cam = Camera()
    rendered = [caster.render(pose, cam) for pose in walk(room, caster, rng, 8)]
    return rendered, [p.thin for p in room.parts]


def predictions(
    views: list[View], errors: Gen5Errors, seed: int = 0
) -> tuple[list[npt.NDArray[np.uint8]], list[npt.NDArray[np.uint8]]]:
    """Return the error-free and the erring network's label images of the views."""
    room = build_room("office", np.random.default_rng(7))
    clean = Network(room.parts, Gen5Errors.none(), np.random.default_rng(seed))
    erring = Network(room.parts, errors, np.random.default_rng(seed))
    rng = np.random.default_rng(seed)
    return [clean.predict(v, rng) for v in views], [erring.predict(v, rng) for v in views]


def test_up_is_the_rooms_up_and_the_floor_lies_flat(scene: Gen5Scene) -> None:
    height = scene.cloud.points.astype(np.float64) @ scene.up
    floor, ceiling = height[scene.truth == Label.FLOOR], height[scene.truth == Label.CEILING]
    assert abs(float(np.linalg.norm(scene.up)) - 1.0) < 1e-9
    assert np.ptp(np.percentile(floor, [1, 99])) < 0.03  # flat, across the whole room
    assert np.abs(floor - np.median(floor)).max() < 0.1  # depth noise at 4 m is 2.4 cm
    assert 2.45 < np.median(ceiling) - np.median(floor) < 2.95  # gen4 rooms are 2.5-2.9 m high
    table = height[scene.truth == Label.TABLE] - np.median(floor)
    assert 0.7 < np.percentile(table, 95) < 0.8  # desk tops at 0.74 m


def test_without_errors_phase_one_is_the_truth_on_objects_and_0_elsewhere() -> None:
    clean = small(camera=QUIET, errors=Gen5Errors.none())
    expected = np.where(np.isin(clean.truth, OBJECT_LABELS), clean.truth, 0)
    assert np.isin(clean.truth, OBJECT_LABELS).sum() > 1000
    assert (clean.cloud.labels != expected).mean() < 0.002  # mixed voxels at contacts


def test_structure_is_unlabelled_and_errors_land_in_the_calibrated_range(
    scene: Gen5Scene,
) -> None:
    assert not np.isin(scene.cloud.labels, [Label.CEILING, Label.FLOOR, Label.WALL]).any()
    objects = np.isin(scene.truth, OBJECT_LABELS)
    wrong = (scene.cloud.labels != scene.truth)[objects].mean()
    assert 0.1 < wrong < 0.5
    assert 0.6 < label_metrics(scene.cloud.labels, scene.truth)["all"]["f1"] < 0.9


def test_the_same_seed_gives_the_same_cloud(scene: Gen5Scene) -> None:
    again, other = small(camera=SMALL), small(seed=2, camera=SMALL)
    assert np.array_equal(again.cloud.points, scene.cloud.points)
    assert np.array_equal(again.cloud.labels, scene.cloud.labels)
    assert np.array_equal(again.cloud.colors, scene.cloud.colors)
    assert len(other.cloud) != len(scene.cloud) or not np.allclose(other.up, scene.up)


def changed(
    views: list[View], errors: Gen5Errors
) -> list[tuple[View, npt.NDArray[np.bool_], npt.NDArray[np.uint8]]]:
    clean, erring = predictions(views, errors)
    return [(v, c != e, e) for v, c, e in zip(views, clean, erring, strict=True)]


def near_outline(view: View, px: float) -> npt.NDArray[np.bool_]:
    """Pixels within `px` of an object's outline, on either side."""
    edges = np.zeros(view.instances.shape, np.uint8)
    inst = view.instances * np.isin(view.labels, OBJECT_LABELS)
    edges[:, 1:] |= inst[:, 1:] != inst[:, :-1]
    edges[1:] |= inst[1:] != inst[:-1]
    dist = cv2.distanceTransform(1 - edges, cv2.DIST_L2, 5)
    return np.asarray(dist <= px + 1.5)


def test_bleed_alone_spreads_object_labels_a_few_pixels_often_far_behind(
    views: tuple[list[View], list[bool]],
) -> None:
    behind = []
    for view, diff, pred in changed(views[0], Gen5Errors().only("bleed")):
        assert (pred[diff] > 0).all()  # bleed only adds labels
        assert near_outline(view, 8)[diff].all()  # within the largest dilation (8 px)
        objects = np.where(np.isin(view.labels, OBJECT_LABELS), view.depth_m, 99).astype(np.float32)
        front = cv2.erode(objects, np.ones((17, 17), np.uint8))  # nearest object within 8 px
        behind += list((view.depth_m - front)[diff])
    assert len(behind) > 500 and np.max(behind) > 1.0  # a wall a metre and more behind


def test_erosion_alone_removes_thin_parts_far_more_than_bulk(
    views: tuple[list[View], list[bool]],
) -> None:
    thin_of_part = np.array([*views[1], False])
    lost = {True: [0, 0], False: [0, 0]}
    for view, diff, pred in changed(views[0], Gen5Errors().only("erosion")):
        assert (pred[diff] == 0).all() and np.isin(view.labels[diff], OBJECT_LABELS).all()
        objects = np.isin(view.labels, OBJECT_LABELS)
        thin = thin_of_part[view.parts]
        for kind in (True, False):
            lost[kind][0] += int((diff & objects & (thin == kind)).sum())
            lost[kind][1] += int((objects & (thin == kind)).sum())
    assert lost[True][1] > 200
    assert lost[True][0] / lost[True][1] > 4 * lost[False][0] / lost[False][1]


def test_missed_blobs_alone_clear_object_pixels_in_blobs(
    views: tuple[list[View], list[bool]],
) -> None:
    sizes = []
    for view, diff, pred in changed(views[0], Gen5Errors().only("blobs")):
        assert (pred[diff] == 0).all() and np.isin(view.labels[diff], OBJECT_LABELS).all()
        n, _, stats, _ = cv2.connectedComponentsWithStats(diff.astype(np.uint8))
        sizes += list(stats[1:n, cv2.CC_STAT_AREA])
    assert len(sizes) > 5 and np.median(sizes) > 50  # blobs of 15-60 px, not single pixels


def test_confusion_alone_relabels_whole_segments_plausibly(
    views: tuple[list[View], list[bool]],
) -> None:
    confused = 0
    for view, diff, pred in changed(views[0], Gen5Errors().only("confusion")):
        for inst in np.unique(view.instances[diff]):
            mask = view.instances == inst
            assert diff[mask].all()  # the whole visible segment
            truth, label = int(view.labels[mask][0]), int(pred[mask][0])
            assert (pred[mask] == label).all() and label in WRONG_CLASS[truth]
            confused += 1
    assert confused >= 3


def test_a_consistently_confused_object_is_confused_in_most_views(
    views: tuple[list[View], list[bool]],
) -> None:
    room = build_room("office", np.random.default_rng(7))
    network = Network(room.parts, Gen5Errors().only("confusion"), np.random.default_rng(0))
    always = {i: t.wrong for i, t in network.traits.items() if t.wrong}
    assert always  # at least one object
    rng, seen, confused = np.random.default_rng(1), 0, 0
    for view in views[0]:
        pred = network.predict(view, rng)
        for inst, wrong in always.items():
            mask = view.instances == inst
            if mask.sum() > 50:
                seen += 1
                confused += int((pred[mask] == wrong).all())
    assert seen >= 3 and confused >= 0.6 * seen  # confusion_always = 0.8


def test_speckle_alone_stays_near_outlines(views: tuple[list[View], list[bool]]) -> None:
    total = 0
    for view, diff, _ in changed(views[0], Gen5Errors().only("speckle")):
        assert near_outline(view, 3 * view.labels.shape[1] / REF_WIDTH)[diff].all()
        total += int(diff.sum())
    assert total > 100


@pytest.mark.parametrize("argv", [["x"], ["0", "0.5"]])
def test_cli_refuses_bad_arguments_in_one_line(
    argv: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("usage:")
