"""ADE20K's 150 classes mapped BY NAME to RECORDING.md labels (for the ADE20K DeepLab network).

The names are ADE20K SceneParsing's `objectInfo150` names (their first synonym is the word in
the model's `labels.txt`); the network's output 0 is "other" and maps to 0. The rules:

- 1 ceiling: the ceiling.
- 2 floor: the floor and what lies flat on it or is walked on (rug, stairs); outdoor ground
  (road, grass, earth...) too: it is the walkable ground plane of the scene.
- 3 wall: the room's vertical shell and what sits flush in it (window, door, curtain, blind,
  column, radiator); building facades.
- 4 table: tables and table-like work surfaces (desk, counter, countertop, kitchen island, bar).
- 5 chair: things to sit on alone (chair, armchair, swivel chair, seat, stool, bench, ottoman).
- 6 person. 7 plant: plants, trees, flowers, flowerpots. 8 sofa: sofas and their cushions.
- 9 tv monitor: screens, monitors, television sets, computers.
- 10 clutter: every other object (furniture we have no label for, appliances, vehicles,
  animals, wall hangings, small things), as PASCAL VOC's other classes map to clutter.
- 0: what has no surface to map or is not part of a room (sky, water, mountains).
"""

from __future__ import annotations

from typing import Final

# objectInfo150 names in class order (class id = position + 1).
ADE20K_NAMES: Final[tuple[str, ...]] = (
    "wall", "building", "sky", "floor", "tree", "ceiling", "road", "bed", "windowpane", "grass",
    "cabinet", "sidewalk", "person", "earth", "door", "table", "mountain", "plant", "curtain",
    "chair", "car", "water", "painting", "sofa", "shelf", "house", "sea", "mirror", "rug",
    "field", "armchair", "seat", "fence", "desk", "rock", "wardrobe", "lamp", "bathtub",
    "railing", "cushion", "base", "box", "column", "signboard", "chest of drawers", "counter",
    "sand", "sink", "skyscraper", "fireplace", "refrigerator", "grandstand", "path", "stairs",
    "runway", "case", "pool table", "pillow", "screen door", "stairway", "river", "bridge",
    "bookcase", "blind", "coffee table", "toilet", "flower", "book", "hill", "bench",
    "countertop", "stove", "palm", "kitchen island", "computer", "swivel chair", "boat", "bar",
    "arcade machine", "hovel", "bus", "towel", "light", "truck", "tower", "chandelier",
    "awning", "streetlight", "booth", "television receiver", "airplane", "dirt track",
    "apparel", "pole", "land", "bannister", "escalator", "ottoman", "bottle", "buffet",
    "poster", "stage", "van", "ship", "fountain", "conveyer belt", "canopy", "washer",
    "plaything", "swimming pool", "stool", "barrel", "basket", "waterfall", "tent", "bag",
    "minibike", "cradle", "oven", "ball", "food", "step", "tank", "trade name", "microwave",
    "pot", "animal", "bicycle", "lake", "dishwasher", "screen", "blanket", "sculpture", "hood",
    "sconce", "vase", "traffic light", "tray", "ashcan", "fan", "pier", "crt screen", "plate",
    "monitor", "bulletin board", "shower", "radiator", "glass", "clock", "flag",
)  # fmt: skip

_BY_LABEL: Final[dict[int, tuple[str, ...]]] = {
    0: ("sky", "water", "sea", "river", "lake", "waterfall", "mountain", "hill"),
    1: ("ceiling",),
    2: (
        "floor", "rug", "road", "sidewalk", "earth", "grass", "field", "sand", "path", "runway",
        "dirt track", "land", "stairs", "stairway", "step",
    ),
    3: (
        "wall", "building", "house", "skyscraper", "windowpane", "door", "screen door",
        "curtain", "blind", "column", "radiator",
    ),
    4: ("table", "desk", "coffee table", "pool table", "counter", "countertop",
        "kitchen island", "bar"),
    5: ("chair", "armchair", "swivel chair", "seat", "stool", "bench", "ottoman"),
    6: ("person",),
    7: ("plant", "tree", "palm", "flower", "pot"),
    8: ("sofa", "cushion"),
    9: ("screen", "crt screen", "monitor", "television receiver", "computer"),
}  # fmt: skip

# Everything not named above is clutter (10).
ADE20K_TO_LABEL: Final[dict[str, int]] = {
    name: next((lab for lab, names in _BY_LABEL.items() if name in names), 10)
    for name in ADE20K_NAMES
}

# Network output index -> label: index 0 is ADE20K's "other", 1..150 the names above.
ADE20K_CLASS_TO_LABEL: Final[tuple[int, ...]] = (0, *(ADE20K_TO_LABEL[n] for n in ADE20K_NAMES))
