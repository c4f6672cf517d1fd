"""Squash court specifications and the 3D line model (paper section V, Fig. 1).

Everything here is in the court frame of the design brief: metres, origin at the floor corner where
the front wall meets the LEFT side wall, x across to the right side wall, y from the front wall to the
back wall, z DOWN (points on the walls above the floor have negative z).

The court is a graph of 22 nodes and 32 edges. Painted lines are modelled by their centre lines
(WSF heights are to the lower edge of a line, so a line's centre is half a line width higher);
wall/floor and wall/wall junctions are at the wall surfaces.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class CourtSpec:
    """Dimensions of one court type, as the governing body's table gives them."""

    name: str
    width_m: float = 6.4
    length_m: float = 9.75
    front_out_lower_m: float = 4.57
    back_out_lower_m: float = 2.13
    service_lower_m: float = 1.78
    tin_upper_m: float = 0.48
    # distance from the back wall to the short line's edge nearest the back wall
    short_line_from_back_m: float = 4.26
    # wall to the inner edge of the service box lines
    box_inside_m: float = 1.6
    line_width_m: float = 0.05
    description: str = field(default="", compare=False)


COURT_SPECS: dict[str, CourtSpec] = {
    "wsf": CourtSpec("wsf", description="WSF singles court"),
    "psa": CourtSpec(
        "psa", tin_upper_m=0.43, description="WSF singles court with the PSA 0.43 m tin"
    ),
    "doubles": CourtSpec("doubles", width_m=7.62, description="WSF doubles court (7.62 m wide)"),
}


def get_spec(name: str) -> CourtSpec:
    try:
        return COURT_SPECS[name]
    except KeyError:
        known = ", ".join(sorted(COURT_SPECS))
        raise ValueError(f"unknown court spec {name!r}; known specs: {known}") from None


@dataclass(frozen=True)
class CourtModel:
    """The court as a graph: `nodes` (V, 3) in metres, `edges` (E, 2) node indices."""

    spec: CourtSpec
    node_names: tuple[str, ...]
    nodes: np.ndarray
    edges: np.ndarray
    edge_names: tuple[str, ...]

    def node(self, name: str) -> np.ndarray:
        return self.nodes[self.node_names.index(name)]

    def edge_lengths_m(self) -> np.ndarray:
        return np.linalg.norm(self.nodes[self.edges[:, 1]] - self.nodes[self.edges[:, 0]], axis=1)

    def keypoints(self) -> dict[str, np.ndarray]:
        return dict(zip(self.node_names, self.nodes, strict=True))

    def painted(self) -> np.ndarray:
        """bool (E,): which edges are painted lines (the rest are junctions of surfaces)."""
        return np.array([name in PAINTED_EDGES for name in self.edge_names])

    def subset(self, edge_names: list[str] | tuple[str, ...]) -> CourtModel:
        """The same court restricted to some edges (e.g. the ones visible in an image)."""
        unknown = set(edge_names) - set(self.edge_names)
        if unknown:
            raise ValueError(f"unknown court edges: {sorted(unknown)}")
        keep = np.array([n in edge_names for n in self.edge_names])
        return CourtModel(
            self.spec,
            self.node_names,
            self.nodes,
            self.edges[keep],
            tuple(n for n, k in zip(self.edge_names, keep, strict=True) if k),
        )


# Edges that are painted 50 mm lines; the rest of the model is wall/floor and wall/wall junctions.
PAINTED_EDGES: tuple[str, ...] = (
    "short_left_outer",
    "short_left_inner",
    "short_right_inner",
    "short_right_outer",
    "half_court",
    "box_left_side",
    "box_left_back",
    "box_right_side",
    "box_right_back",
    "tin",
    "service",
    "front_out",
    "left_out",
    "right_out",
    "back_out",
)


def court_model(spec: CourtSpec | str = "wsf") -> CourtModel:
    """Build the 22-node, 32-edge court graph for a spec."""
    if isinstance(spec, str):
        spec = get_spec(spec)
    half_line = spec.line_width_m / 2.0
    w, length = spec.width_m, spec.length_m
    short_y = length - spec.short_line_from_back_m - half_line
    box_back_y = short_y + half_line + spec.box_inside_m + half_line
    box_left_x = spec.box_inside_m + half_line
    box_right_x = w - box_left_x
    centre_x = w / 2.0
    z_tin = -(spec.tin_upper_m - half_line)
    z_service = -(spec.service_lower_m + half_line)
    z_front_out = -(spec.front_out_lower_m + half_line)
    z_back_out = -(spec.back_out_lower_m + half_line)

    named_nodes: dict[str, tuple[float, float, float]] = {
        # floor
        "floor_front_left": (0.0, 0.0, 0.0),
        "floor_front_right": (w, 0.0, 0.0),
        "floor_back_left": (0.0, length, 0.0),
        "floor_back_right": (w, length, 0.0),
        "short_left": (0.0, short_y, 0.0),
        "T": (centre_x, short_y, 0.0),
        "short_right": (w, short_y, 0.0),
        "half_back": (centre_x, length, 0.0),
        "box_left_short": (box_left_x, short_y, 0.0),
        "box_left_inner_back": (box_left_x, box_back_y, 0.0),
        "box_left_wall_back": (0.0, box_back_y, 0.0),
        "box_right_short": (box_right_x, short_y, 0.0),
        "box_right_inner_back": (box_right_x, box_back_y, 0.0),
        "box_right_wall_back": (w, box_back_y, 0.0),
        # front wall
        "tin_left": (0.0, 0.0, z_tin),
        "tin_right": (w, 0.0, z_tin),
        "service_left": (0.0, 0.0, z_service),
        "service_right": (w, 0.0, z_service),
        "front_out_left": (0.0, 0.0, z_front_out),
        "front_out_right": (w, 0.0, z_front_out),
        # back wall
        "back_out_left": (0.0, length, z_back_out),
        "back_out_right": (w, length, z_back_out),
    }
    edge_pairs: list[tuple[str, str, str]] = [
        # floor: wall/floor junctions
        ("front_floor", "floor_front_left", "floor_front_right"),
        ("left_floor_front", "floor_front_left", "short_left"),
        ("left_floor_box", "short_left", "box_left_wall_back"),
        ("left_floor_back", "box_left_wall_back", "floor_back_left"),
        ("right_floor_front", "floor_front_right", "short_right"),
        ("right_floor_box", "short_right", "box_right_wall_back"),
        ("right_floor_back", "box_right_wall_back", "floor_back_right"),
        ("back_floor_left", "floor_back_left", "half_back"),
        ("back_floor_right", "half_back", "floor_back_right"),
        # floor: painted lines
        ("short_left_outer", "short_left", "box_left_short"),
        ("short_left_inner", "box_left_short", "T"),
        ("short_right_inner", "T", "box_right_short"),
        ("short_right_outer", "box_right_short", "short_right"),
        ("half_court", "T", "half_back"),
        ("box_left_side", "box_left_short", "box_left_inner_back"),
        ("box_left_back", "box_left_inner_back", "box_left_wall_back"),
        ("box_right_side", "box_right_short", "box_right_inner_back"),
        ("box_right_back", "box_right_inner_back", "box_right_wall_back"),
        # front wall: painted lines and the wall/wall corners
        ("tin", "tin_left", "tin_right"),
        ("service", "service_left", "service_right"),
        ("front_out", "front_out_left", "front_out_right"),
        ("front_left_corner_low", "floor_front_left", "tin_left"),
        ("front_left_corner_mid", "tin_left", "service_left"),
        ("front_left_corner_high", "service_left", "front_out_left"),
        ("front_right_corner_low", "floor_front_right", "tin_right"),
        ("front_right_corner_mid", "tin_right", "service_right"),
        ("front_right_corner_high", "service_right", "front_out_right"),
        # side walls
        ("left_out", "front_out_left", "back_out_left"),
        ("right_out", "front_out_right", "back_out_right"),
        # back wall
        ("back_out", "back_out_left", "back_out_right"),
        ("back_left_corner", "floor_back_left", "back_out_left"),
        ("back_right_corner", "floor_back_right", "back_out_right"),
    ]
    names = tuple(named_nodes)
    index = {n: i for i, n in enumerate(names)}
    return CourtModel(
        spec=spec,
        node_names=names,
        nodes=np.array([named_nodes[n] for n in names], dtype=np.float64),
        edges=np.array([(index[a], index[b]) for _, a, b in edge_pairs], dtype=np.int64),
        edge_names=tuple(e for e, _, _ in edge_pairs),
    )


@dataclass(frozen=True)
class LineSamples:
    """Points sampled along the court's edges, stored edge after edge.

    `points` (M, 3) in metres; the samples of edge e are `points[offsets[e]:offsets[e + 1]]` and
    include both of the edge's end nodes, so consecutive samples within an edge form sub-segments.
    """

    points: np.ndarray
    offsets: np.ndarray

    @property
    def n_points(self) -> int:
        return int(self.points.shape[0])


def sample_edges(model: CourtModel, spacing_m: float) -> LineSamples:
    """Sample every edge at (at most) `spacing_m` metres, end nodes included."""
    if not spacing_m > 0:
        raise ValueError(f"spacing_m must be positive, got {spacing_m}")
    chunks = []
    offsets = [0]
    for a, b in model.edges:
        start, end = model.nodes[a], model.nodes[b]
        n = max(2, int(np.ceil(np.linalg.norm(end - start) / spacing_m)) + 1)
        s = np.linspace(0.0, 1.0, n)[:, None]
        chunks.append(start + s * (end - start))
        offsets.append(offsets[-1] + n)
    return LineSamples(np.concatenate(chunks), np.asarray(offsets, dtype=np.int64))


def spacing_for_image(image_width_px: int, reference_spacing_m: float = 0.07) -> float:
    """Sample spacing for an image width: ~1500 samples on the full court at 1920 px wide.

    A court filling a 1920 px image is ~100 px/m at its far end, so 7 cm keeps neighbouring samples a
    few pixels apart; smaller images get proportionally fewer samples.
    """
    if image_width_px <= 0:
        raise ValueError(f"image width must be positive, got {image_width_px}")
    return reference_spacing_m * 1920.0 / float(image_width_px)


def floor_grid(spec: CourtSpec | str = "wsf", m: int = 16, n: int = 16) -> np.ndarray:
    """G_p^{m x n}: a regular m x n grid of floor points spanning the playing surface, (m*n, 3)."""
    if isinstance(spec, str):
        spec = get_spec(spec)
    xs = np.linspace(0.0, spec.width_m, m)
    ys = np.linspace(0.0, spec.length_m, n)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    return np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)


def bounding_box_grid(model: CourtModel, per_axis: int = 5) -> np.ndarray:
    """G_b: the court's 3D bounding box sampled on a regular grid in all three dimensions."""
    lo, hi = model.nodes.min(axis=0), model.nodes.max(axis=0)
    axes = [np.linspace(lo[i], hi[i], per_axis) for i in range(3)]
    grid = np.meshgrid(*axes, indexing="ij")
    return np.stack([g.ravel() for g in grid], axis=1)
