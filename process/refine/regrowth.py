"""Step 4: regrowth of unlabelled points around each object (paper section 2.4.2, PAPER.md).

Clusters are grouped into objects first: clusters of one class whose bounding boxes, grown by
`gap_m`, overlap are one object (DBSCAN splits a table with a missed patch across its top
into pieces; the paper's r2 is an object's size, Table 10). A point with label 0 joins a
cluster when it lies within r1 (the eps chosen for the cluster's class) of a point already in
it and inside its object: the object's axis-aligned box grown by r1. That box lies within r2
(half its diagonal, Eq. 7-8) of its centre, the paper's sphere, but does not reach into the
neighbours beside a long table. Growth runs in waves, each wave testing the remaining
unlabelled points against the points that joined in the previous one, until no point joins.
A point that two clusters reach in the same wave goes to the nearer one: the cluster of its
nearest qualifying frontier point.

Growth first follows surfaces (`surface_link`): waves of a few point spacings, until none
joins, before waves of r1. At r1 (9-11 cm at 60k object points) a seated person reaches across
the 3-7 cm between his back and his chair's, and his waves, nearer, take the unlabelled points
of the chair's back before the chair's own labelled points further along it do; along the
surface the chair's points reach them first (generator 4 at 60k, 60 fresh rooms: +0.0020 F1
on average, 39 -> 42 of them >= 0.95; most of the rest changes a few points either way).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from capture.recording import Label
from process.refine.graph import kd_tree, point_spacing
from process.refine.objects import group_objects

_CANDIDATES = 8  # frontier points examined per unlabelled point and wave, nearest first
ON_HOST_SHARE = 0.95  # of a nested cluster's points near its host's for adoption (_adopt)
TOUCH_SHARE = 0.2  # ... and this share within half the host's r1 of them: lying on it
_FLOOR_PERCENTILE = 0.5  # the floor under the objects: this low a percentile of their heights
# a table's top surface (table_tops): its highest layer this thick holding this share of its
# points, where that reaches this percentile of their heights
TOP_LAYER_M, TOP_LAYER_SHARE, TOP_PERCENTILE = 0.02, 0.1, 90.0
# classes that stand on the floor, on legs, bases and stems: their boxes reach down to it. A
# monitor or clutter stands on a table: reaching down, it would take the table top under it.
STANDING = (Label.TABLE, Label.CHAIR, Label.PERSON, Label.PLANT, Label.SOFA)
# (nested class, host class) never adopted (_adopt): a seated person's box holds his chair, whose
# back and seat the network splits into pieces small enough to pass for patches on him
SEATED = ((Label.CHAIR, Label.PERSON),)


@dataclass(frozen=True)
class Regrowth:
    """Labels and clusters after regrowth, and what grew."""

    labels: npt.NDArray[np.uint8]  # (N,)
    clusters: npt.NDArray[np.int32]  # (N,)
    regrown: npt.NDArray[np.intp]  # indices of the points that joined a cluster
    r2_m: dict[int, float]  # cluster id -> r2 of its object
    objects: dict[int, int]  # cluster id -> object id (1..)
    waves: int
    adopted: npt.NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    # indices of the points of nested clusters that took their host's class
    above_tables: int = 0  # points left 0 in tables' boxes above table_top_m, below r1
    rejoined: int = 0  # points that joined an object of their prior class beyond r1 (`rejoin`)


def regrow(
    points: npt.NDArray[np.float32],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    *,
    r1_m: dict[int, float],
    gap_m: float = 0.0,
    bridge_m: float = 0.0,
    up: npt.NDArray[np.float64] | None = None,
    prior: npt.NDArray[np.uint8] | None = None,
    keep_out: npt.NDArray[np.bool_] | None = None,
    leaf: npt.NDArray[np.bool_] | None = None,
    nest: bool = False,
    adopt_ratio: float = 0.0,
    patch_max_m: float = 0.0,
    table_top_m: float = 0.0,
    rejoin: bool = False,
    surface_link: float = 0.0,
) -> Regrowth:
    """Grow every cluster (clusters > 0) over the points with label 0.

    Args:
        points: (N, 3) the object cloud.
        labels: (N,) class per point, 0 = unlabelled (the candidates).
        clusters: (N,) cluster id per point, 0 = none; every cluster has one class.
        r1_m: class label -> r1 (the class's chosen eps).
        gap_m: clusters of one class whose boxes come this close are one object.
        bridge_m: ... and up to this far apart when a patch of another class (a box of at
            most `patch_max_m` diagonal) touches both (objects.py); 0: off.
        up: gravity-up; boxes are then taken in a frame with z up, and the box of each
            object of a class that stands on the floor (STANDING) reaches down to it (the
            lowest points): furniture stands on legs, bases and stems that a segmentation
            misses first.
        prior: (N,) the network's labels (phase I), if given: growth runs twice, first
            letting a point join only a cluster of its prior class (any, if its prior is 0),
            then any. A correct point that DBSCAN set to 0 (noise at the edge of a thin
            part) goes back to its own object before a neighbour of another class reaches
            it; a wrong-class speck, whose class has no object near, is relabelled after.
        keep_out: (N,) points that join no cluster though labelled 0 (the refinement passes
            the network calls ceiling, floor or wall: on TUM fr1_rpy, a seated person otherwise
            grows over the points around him that the network calls wall, his chair's among them).
        leaf: (N,) points that may join a cluster but pass growth on to no other point: the
            unlabelled points on the floor plane. Growth reaches them from the legs standing
            on them, and the box of an object standing on the floor reaches down to it; so a
            table's growth crept along a floor fused from raw depth, which lies in two layers
            1 cm apart whose upper one the noise band gives back (generator 5's meeting room
            at 60k: 2,400 floor points made table). With `surface_link` they join only in
            the waves along surfaces, from a leg's foot, not across r1: a chair's r1 reached
            the layer under its whole seat (that room: 746 floor points made chair).
        nest: an object whose box lies inside the box of an object of another class (a
            wrong-class patch on a television, a table leg called chair) takes back only the
            points the network gave its class (`prior`), none of the unlabelled ones: in the
            simulator's room 3 a 0.3 m chair patch on a wall-mounted screen otherwise took
            3,000 of the screen's unlabelled points. Without `prior` it grows over nothing.
        adopt_ratio: with `nest`, a nested cluster whose largest host object holds at least
            this many times its points, and that lies on it (`ON_HOST_SHARE`), takes the
            host's class first, and grows as part of it (a chair's back top called clutter);
            0: never.
        patch_max_m: with `nest`, only a cluster whose own box has at most this diagonal is
            nested: a patch. A larger one is an object in its own right, as a chair under a
            seated person is (generator 4: 15,700 of an office's 34,000 chair points went to
            the people, the chairs yielding their unlabelled points and being adopted); 0: any.
        table_top_m: with `up`, a table's box reaches only this far above its top, not r1:
            what stands on a table is not table (on fused sim maps, clutter the network
            labelled right that DBSCAN left as specks grew into the table); 0: r1. The top is
            the table's surface (`table_tops`), not its highest point.
        rejoin: with `prior`, after growth a point still 0 whose prior class has an object
            (not a table) whose box holds it, and no object of another class's box, joins
            that object however far from it (chair legs whose upper half the network
            missed, more than r1 below the seat); a table's box shelters chairs under it.
        surface_link: in each pass, waves reach at most this many point spacings (the median
            nearest-neighbour distance of `points`) until none joins, then r1; 0: r1 only.
    """
    labels, clusters = labels.copy(), clusters.copy()
    if up is not None:
        points = (points.astype(np.float64) @ frame(up).T).astype(np.float32)
    ids = np.unique(clusters[clusters > 0])
    if len(ids) == 0:
        return Regrowth(labels, clusters, np.zeros(0, np.intp), {}, {}, 0)
    table = _cluster_table(points, labels, clusters, ids, r1_m, gap_m, bridge_m, patch_max_m)
    hosts = _hosts(table, patch_max_m) if nest else np.zeros((len(ids), len(ids)), bool)
    nested = np.asarray(hosts.any(axis=1), bool)
    adopted = (
        _adopt(table, hosts, points, clusters, ids, adopt_ratio, upright=up is not None)
        if nested.any()
        else []
    )
    host_of = dict(adopted)
    for nested_row, host in adopted:
        for _ in range(len(host_of)):  # a host adopted in turn passes on its own host's class
            host = host_of.get(host, host)
        labels[clusters == ids[nested_row]] = table.label[nested_row] = table.label[host]
        nested[nested_row] = False
    reach = table.high.copy()  # the boxes' tops at r1, before tables' are cut
    if up is not None and len(points):
        floor = float(np.percentile(points[:, 2], _FLOOR_PERCENTILE))
        stands = np.isin(table.label, STANDING)
        table.low[stands, 2] = np.minimum(table.low[stands, 2], floor)
        if table_top_m > 0:
            desks = np.flatnonzero(table.label == Label.TABLE)
            top = np.full(table.object.max() + 1, -np.inf)  # each object's top surface
            np.maximum.at(top, table.object[desks], table_tops(points[:, 2], clusters, ids[desks]))
            table.high[desks, 2] = top[table.object[desks]] + np.minimum(
                table_top_m, table.r1[desks]
            )
    lookup = np.searchsorted(ids, clusters)  # row of each clustered point in the table
    grown: list[npt.NDArray[np.intp]] = []
    waves = 0
    steps = [np.inf]  # each pass's waves reach r1 ...
    if surface_link > 0:  # ... after waves along surfaces
        steps.insert(0, surface_link * point_spacing(points))
    for own in (None,) if prior is None else (prior, None):  # its own class first, then any
        for step in steps:
            frontier = np.flatnonzero((clusters > 0) if leaf is None else (clusters > 0) & ~leaf)
            open_ = (labels == 0) if keep_out is None else (labels == 0) & ~keep_out
            if leaf is not None and step == np.inf and surface_link > 0:
                open_ &= ~leaf  # leaves join along surfaces only: not under a seat across r1
            open_ = np.flatnonzero(open_)
            while len(frontier) and len(open_):
                joined, row = _wave(
                    points, frontier, lookup[frontier], open_, table, own, nested, step
                )
                if len(joined) == 0:
                    break
                labels[joined], clusters[joined] = table.label[row], ids[row].astype(np.int32)
                lookup[joined] = row
                grown.append(joined)
                open_ = np.setdiff1d(open_, joined, assume_unique=True)
                frontier, waves = (joined if leaf is None else joined[~leaf[joined]]), waves + 1
    rejoined = 0
    if rejoin and prior is not None:  # what growth left: points inside their class's object
        open_ = (labels == 0) if keep_out is None else (labels == 0) & ~keep_out
        joined, row = _rejoin(points, np.flatnonzero(open_), prior, table, nested)
        labels[joined], clusters[joined] = table.label[row], ids[row].astype(np.int32)
        grown.append(joined)
        rejoined = len(joined)
    regrown = np.concatenate(grown) if grown else np.zeros(0, np.intp)
    r2 = {int(i): float(r) for i, r in zip(ids, table.r2, strict=True)}
    objects = {int(i): int(o) + 1 for i, o in zip(ids, table.object, strict=True)}
    rows = [row for row, _ in adopted]
    taken = np.flatnonzero(np.isin(clusters, ids[rows])) if rows else np.zeros(0, np.intp)
    above = 0 if table_top_m <= 0 or up is None else _above(points, labels, table, reach)
    return Regrowth(labels, clusters, np.sort(regrown), r2, objects, waves, taken, above, rejoined)


def _rejoin(
    points: npt.NDArray[np.float32],
    open_: npt.NDArray[np.intp],
    prior: npt.NDArray[np.uint8],
    table: _Clusters,
    nested: npt.NDArray[np.bool_],
) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """Return the open points inside an object of their prior class only, and the row each joins.

    Of nested boxes of one class the smallest wins; a point inside an object of another class
    too (a table leg the network called chair beside a chair) is left alone.
    """
    xyz = points[open_].astype(np.float64)
    row = np.full(len(open_), -1, np.intp)
    contested = np.zeros(len(open_), bool)  # inside an object of another class too
    volume = np.prod(table.high - table.low, axis=1)
    for r in np.argsort(-volume):  # the smallest box containing a point last, so it wins
        if nested[r]:
            continue
        inside = np.all((xyz >= table.low[r]) & (xyz <= table.high[r]), axis=1)
        mine = prior[open_] == table.label[r]
        if table.label[r] != Label.TABLE:  # a table's box shelters chairs under it
            row[inside & mine] = r
        contested |= inside & ~mine
    hit = (row >= 0) & ~contested
    return open_[hit], row[hit]


def _above(
    points: npt.NDArray[np.float32],
    labels: npt.NDArray[np.uint8],
    table: _Clusters,
    reach: npt.NDArray[np.float64],
) -> int:
    """Return how many points left 0 lie between a table box's cut top and its r1 top."""
    rows = np.flatnonzero(reach[:, 2] > table.high[:, 2])
    xyz = points[labels == 0].astype(np.float64)
    held = np.zeros(len(xyz), bool)
    for row in rows:
        held |= np.all((xyz >= table.low[row]) & (xyz <= reach[row]), axis=1) & (
            xyz[:, 2] > table.high[row, 2]
        )
    return int(held.sum())


@dataclass(frozen=True)
class _Clusters:
    label: npt.NDArray[np.uint8]  # (C,) class of each cluster
    object: npt.NDArray[np.int64]  # (C,) object of each cluster, 0..
    low: npt.NDArray[np.float64]  # (C, 3) its object's box grown by r1
    high: npt.NDArray[np.float64]  # (C, 3)
    r1: npt.NDArray[np.float64]  # (C,)
    r2: npt.NDArray[np.float64]  # (C,) half the diagonal of its object's box
    own_low: npt.NDArray[np.float64]  # (C, 3) the cluster's own box
    own_high: npt.NDArray[np.float64]  # (C, 3)


def _cluster_table(
    points: npt.NDArray[np.float32],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    ids: npt.NDArray[np.int32],
    r1_m: dict[int, float],
    gap_m: float,
    bridge_m: float = 0.0,
    patch_max_m: float = 0.0,
) -> _Clusters:
    member = np.flatnonzero(clusters > 0)
    row = np.searchsorted(ids, clusters[member])
    xyz = points[member].astype(np.float64)
    low = np.full((len(ids), 3), np.inf)
    high = np.full((len(ids), 3), -np.inf)
    np.minimum.at(low, row, xyz)
    np.maximum.at(high, row, xyz)
    label = np.zeros(len(ids), np.uint8)
    label[row] = labels[member]
    r1 = np.array([r1_m.get(int(c), 0.0) for c in label])
    obj = group_objects(
        label, low, high, gap_m=gap_m, r1=r1, bridge_m=bridge_m, patch_max_m=patch_max_m
    )
    o_low = np.full((obj.max() + 1, 3), np.inf)
    o_high = np.full((obj.max() + 1, 3), -np.inf)
    np.minimum.at(o_low, obj, low)
    np.maximum.at(o_high, obj, high)
    r2 = np.linalg.norm(o_high - o_low, axis=1)[obj] / 2
    grown_low, grown_high = o_low[obj] - r1[:, None], o_high[obj] + r1[:, None]
    return _Clusters(label, obj, grown_low, grown_high, r1, r2, low, high)


def table_tops(
    heights: npt.NDArray[np.floating], clusters: npt.NDArray[np.int32], ids: npt.NDArray[np.int32]
) -> npt.NDArray[np.float64]:
    """Return the top surface's height of each table cluster in `ids` (sorted, all present).

    A table's points lie mostly on its top, and the labels it bled onto a cup or a monitor's
    foot standing on it lie above (a fused map of a simulated recording, seed 43: table labels
    on a cup's rim 11 cm over the top opened two cups beside it to the table's growth). Where
    the highest TOP_LAYER_M layer holding TOP_LAYER_SHARE of the cluster's points reaches its
    TOP_PERCENTILE (the top surface), the top is the higher of the two; a cluster with no such
    layer up there (legs whose top the network missed, legs and a stretcher) keeps its highest
    point. Never above the cluster's highest point.
    """
    tops = np.empty(len(ids), np.float64)
    if len(ids) == 0:
        return tops
    member = np.flatnonzero(np.isin(clusters, ids))
    group = np.searchsorted(ids, clusters[member])
    order = np.lexsort((heights[member], group))
    counts = np.bincount(group, minlength=len(ids))
    for row, h in enumerate(
        np.split(heights[member[order]].astype(np.float64), np.cumsum(counts)[:-1])
    ):
        tops[row] = h[-1]
        layer = np.floor(h / TOP_LAYER_M).astype(np.int64)
        level, n = np.unique(layer, return_counts=True)
        dense = level[n >= TOP_LAYER_SHARE * len(h)]
        if len(dense) == 0:
            continue
        surface = float(h[layer == dense.max()].max())
        upper = float(h[int(TOP_PERCENTILE / 100 * (len(h) - 1))])
        if surface >= upper - TOP_LAYER_M:
            tops[row] = min(tops[row], max(surface, upper))
    return tops


def frame(up: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Return a rotation whose third row is the unit `up` (points @ R.T have z along up)."""
    z = np.asarray(up, np.float64) / np.linalg.norm(up)
    x = np.cross([0.0, 1.0, 0.0] if abs(z[1]) < 0.9 else [1.0, 0.0, 0.0], z)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z])


def _hosts(table: _Clusters, patch_max_m: float = 0.0) -> npt.NDArray[np.bool_]:
    """Return [a, b]: cluster a lies inside the box of cluster b's object, of another class.

    The cluster's own box is tested against the other object's box grown by r1 (a patch on a
    screen takes a few wall points behind it along), or a clutter cluster's own box grown by r1.
    The cluster's, not its object's: a table-labelled patch on a chair's back 15 cm from the
    table is one object with the table.
    Nothing is nested in a table: the clutter on it and the chairs under it are objects (on
    TSDF maps of degraded sim keyframes, clutter then lost 99 points to the table). With
    `patch_max_m`, only a cluster whose own box has at most that diagonal is nested: a patch.
    """
    low, high = table.own_low, table.own_high
    host_low, host_high = table.low.copy(), table.high.copy()
    # clutter is many small things: its object, chained over a cluttered desk, spans what
    # stands between them (TUM fr1_rpy: a 2.2-2.8 m clutter object nested the monitor in 2 of
    # 10 runs of 1 um jitter); a clutter cluster hosts in its own box only
    pile = table.label == Label.CLUTTER
    host_low[pile] = table.own_low[pile] - table.r1[pile, None]
    host_high[pile] = table.own_high[pile] + table.r1[pile, None]
    inside = np.all((host_low[None] <= low[:, None]) & (high[:, None] <= host_high[None]), axis=2)
    if patch_max_m > 0:  # larger, it is an object of its own (a chair under a seated person)
        inside &= (np.linalg.norm(high - low, axis=1) <= patch_max_m)[:, None]
    inside &= table.label[:, None] != table.label[None]
    inside &= table.label[None] != Label.TABLE  # a table carries and shelters real objects
    hosts: npt.NDArray[np.bool_] = inside
    return hosts


def _adopt(
    table: _Clusters,
    hosts: npt.NDArray[np.bool_],
    points: npt.NDArray[np.float32],
    clusters: npt.NDArray[np.int32],
    ids: npt.NDArray[np.int32],
    ratio: float,
    *,
    upright: bool = False,
) -> list[tuple[int, int]]:
    """Return (nested row, host row) for nested clusters on a host object that outweighs them.

    On: `ON_HOST_SHARE` of the cluster's points lie within 2 r1 of the host object's points, as
    a wrong-class patch on a screen or a chair's back does, and `TOUCH_SHARE` within r1 / 2: a
    patch lies on its host, a seat under a seated person's thighs only near them (generator 3's
    room 2: 1,519 chair points had become person; on the 58 suite clouds the rule stops 13 of
    113 adoptions, and 2,200 more points come out right than wrong). A sofa's seat called chair
    between its back and front touches them only at its edges (28 % within r1 / 2) and is
    adopted. A chair under a seated person lies in the person's box and is outweighed, but only
    2-89 % of its points are near the person (generator 3: adoption alone turned 13,600 chair
    points into person in one room). The host must outweigh the cluster's own object, not the
    cluster alone, unless it is a table's (table objects chain over gaps to the table patches on
    chairs beside them) and, with `upright` (z along up), not taller than wide: a chair's leg
    beside a box on the floor is part of a chair larger than the box, a table's leg beside a
    chair part of the table.

    A chair's piece in a person's box is never adopted (`SEATED`): the network misses blobs of a
    seated person's chair, and the pieces of its back and seat left (0.1-0.5 m, 60-900 points)
    lie on him as a patch would; some chair-labelled patches on a lap or a torso stay chair too
    (60 fresh generator-4 rooms at 60k: +0.0015 F1 on average, -0.0016 to +0.032, 42 -> 43 of
    them >= 0.95; generator 3's room 8 -0.0021: a chair-labelled patch of 431 points on a person).
    """
    if ratio <= 0:
        return []
    sizes = np.bincount(np.searchsorted(ids, clusters[clusters > 0]), minlength=len(ids))
    per_object = np.bincount(table.object, weights=sizes)
    out = []
    for row in np.flatnonzero(hosts.any(axis=1)):
        candidates = np.flatnonzero(hosts[row])
        host = int(candidates[np.argmax(per_object[table.object[candidates]])])
        if (table.label[row], table.label[host]) in SEATED:
            continue
        # a part of a larger object of its own class is that object's, not a patch on the
        # host (a chair's leg beside a box); a table's object chains over gaps to the
        # table-labelled patches on chairs beside it, so a table cluster is weighed alone,
        # unless it is taller than wide: a piece of a leg (generator 4's kitchen at 500k:
        # chairs pushed in took 5,640 points of the table's legs)
        extent = table.own_high[row] - table.own_low[row]
        leg = upright and extent[2] > max(extent[0], extent[1])  # taller than wide
        alone = table.label[row] == Label.TABLE and not leg
        own = sizes[row] if alone else per_object[table.object[row]]
        if per_object[table.object[host]] < ratio * own:
            continue
        host_points = points[np.isin(clusters, ids[table.object == table.object[host]])]
        near, _ = kd_tree(host_points).query(
            points[clusters == ids[row]], distance_upper_bound=2 * table.r1[host]
        )
        touching = float(np.mean(near <= table.r1[host] / 2))
        if float(np.mean(np.isfinite(near))) >= ON_HOST_SHARE and touching >= TOUCH_SHARE:
            out.append((int(row), host))
    return out


def _wave(
    points: npt.NDArray[np.float32],
    frontier: npt.NDArray[np.intp],
    frontier_row: npt.NDArray[np.intp],
    open_: npt.NDArray[np.intp],
    table: _Clusters,
    prior: npt.NDArray[np.uint8] | None = None,
    nested: npt.NDArray[np.bool_] | None = None,
    step: float = np.inf,
) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """Return the open points that join in this wave and the cluster row each joins.

    A point joins a cluster with a frontier point within the smaller of its r1 and `step`. With
    `prior`, a point with a prior label joins only a cluster of that class. A `nested` cluster
    takes only points whose prior is its class.
    """
    k = min(_CANDIDATES, len(frontier))
    reach = min(float(table.r1.max()), step)
    distance, nearest = kd_tree(points[frontier]).query(
        points[open_], k=k, distance_upper_bound=reach, workers=-1
    )
    distance, nearest = distance.reshape(len(open_), k), nearest.reshape(len(open_), k)
    near = np.flatnonzero(np.isfinite(distance[:, 0]))  # anything within the largest r1
    distance, nearest = distance[near], nearest[near]
    hit = np.isfinite(distance)
    rows = np.where(hit, frontier_row[np.minimum(nearest, len(frontier) - 1)], 0)
    xyz = points[open_[near]].astype(np.float64)[:, None, :]
    inside = np.all((xyz >= table.low[rows]) & (xyz <= table.high[rows]), axis=2)
    ok = hit & (distance <= np.minimum(table.r1[rows], step)) & inside
    if prior is not None:
        own = prior[open_[near]][:, None]
        ok &= (own == 0) | (own == table.label[rows])
    if nested is not None and nested.any():
        mine = False if prior is None else prior[open_[near]][:, None] == table.label[rows]
        ok &= ~nested[rows] | mine
    joins = ok.any(axis=1)
    first = ok[joins].argmax(axis=1)  # nearest qualifying frontier point
    return open_[near[joins]], rows[joins, first]
