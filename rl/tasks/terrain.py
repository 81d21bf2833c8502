"""Box-geometry rough terrain for the walk task: a grid of tiles, one difficulty level per row.

Why boxes, not a heightfield: box-box and box-primitive collisions are analytic and cheap in MuJoCo
C and in MuJoCo Warp, while heightfield collisions go through a per-prism convex path (slow on Warp,
and a fine heightfield over a 60 m x 42 m field is a large model). All boxes are static geoms of the
world body, so MuJoCo's broadphase treats the terrain as one body and its midphase BVH keeps the
contact search logarithmic in the number of boxes (measured in ``docs/environments.md``).

Layout: ``num_rows`` levels (row r = difficulty r / (num_rows - 1)) along world x, ``num_cols``
columns along y, column c of type ``types[c % len(types)]``. Every tile is ``tile_size_m`` square,
centred at :meth:`Terrain.tile_center_xy`, with a flat spawn platform in its centre. Tile types:

- ``flat``: the floor itself.
- ``slope_up``: an inverted pyramid (a pit) of four tilted slabs rising from the platform to the
  tile edge with slope ``s`` (walking out of the centre goes up); the union of the slabs' solids is
  the max of the four planes, exactly the pit's surface.
- ``slope_down``: a ridge along y, flat top over the platform, two tilted slabs down to the floor
  at the tile's x edges (walking out along x goes down). (A pyramid hill is the *min* of planes,
  which a union of boxes cannot form without stepping it.)
- ``rough``: a grid of small boxes of random heights.
- ``obstacles``: random discrete boxes around the platform.
- ``stairs_up``: square rings of stairs rising outward from a floor-level platform (4 boxes a step).
- ``stairs_down``: a stepped pyramid, platform on top (nested boxes, one a step).

The same geometry, rasterised analytically (vertical ray against each oriented box), is the
:class:`HeightMap` the height scan reads; tests check it against MuJoCo's ray cast.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np
import torch

TILE_TYPES = (
    "flat",
    "slope_up",
    "slope_down",
    "rough",
    "obstacles",
    "stairs_up",
    "stairs_down",
)
"""Tile types the terrain can hold (:attr:`TerrainConfig.types` picks and orders them)."""


@dataclass(frozen=True)
class TerrainConfig:
    """Geometry of the terrain grid; difficulty d = row / (num_rows - 1) scales each type."""

    num_rows: int = 10  # difficulty levels (rows along world x) [-]
    num_cols: int = 7  # tiles per level (columns along world y) [-]
    types: tuple[str, ...] = TILE_TYPES  # tile type of column c: types[c % len(types)]
    tile_size_m: float = 6.0  # side of a square tile [m]
    platform_half_m: float = 0.75  # half side of the flat spawn platform in a tile's centre [m]
    stair_width_m: float = 0.3  # tread depth of a stair [m]
    stair_height_range_m: tuple[float, float] = (0.05, 0.23)  # riser at level 0 / top level [m]
    slope_range: tuple[float, float] = (0.0, 0.4)  # slope rise/run at level 0 / top level [-]
    rough_cell_m: float = 0.6  # side of one rough-terrain box [m]
    rough_height_range_m: tuple[float, float] = (0.02, 0.10)  # max box height, level 0 / top [m]
    obstacle_count: int = 16  # discrete obstacles per tile [-]
    obstacle_size_range_m: tuple[float, float] = (0.4, 1.0)  # side of an obstacle [m]
    obstacle_height_range_m: tuple[float, float] = (0.05, 0.20)  # max height, level 0 / top [m]
    slab_thickness_m: float = 0.2  # thickness of the tilted slope slabs [m]
    height_map_resolution_m: float = 0.05  # cell of the rasterised height map [m]
    margin_m: float = 2.0  # floor (height 0) kept around the grid in the height map [m]
    seed: int = 0  # random generator of the rough and obstacle tiles [-]

    def __post_init__(self) -> None:
        unknown = sorted(set(self.types) - set(TILE_TYPES))
        if unknown or not self.types:
            raise ValueError(f"terrain types {unknown or '()'} unknown; known: {TILE_TYPES}")
        if self.num_rows < 2 or self.num_cols < 1:
            raise ValueError(
                f"terrain needs num_rows >= 2 and num_cols >= 1, got {self.num_rows} x "
                f"{self.num_cols}"
            )
        if not 0 < 2 * self.platform_half_m < self.tile_size_m:
            raise ValueError(
                f"terrain platform_half_m {self.platform_half_m} must be in (0, tile_size_m/2)"
            )
        if self.height_map_resolution_m <= 0:
            raise ValueError("terrain height_map_resolution_m must be > 0 m")

    def difficulty(self, row: int) -> float:
        """Difficulty in [0, 1] of level ``row``."""
        return row / (self.num_rows - 1)

    def stair_height_m(self, row: int) -> float:
        """Riser height of the stairs of level ``row`` [m] (0.23 m at the top level by default)."""
        low, high = self.stair_height_range_m
        return low + (high - low) * self.difficulty(row)

    def slope(self, row: int) -> float:
        """Slope rise / run of level ``row`` [-]."""
        low, high = self.slope_range
        return low + (high - low) * self.difficulty(row)


@dataclass(frozen=True)
class Box:
    """One terrain box: centre [m], half sizes [m], orientation quaternion (w, x, y, z), tile."""

    pos: tuple[float, float, float]
    half: tuple[float, float, float]
    quat: tuple[float, float, float, float]
    tile: tuple[int, int]  # (row, col)


def _quat_about_y(angle_rad: float) -> tuple[float, float, float, float]:
    return (math.cos(angle_rad / 2), 0.0, math.sin(angle_rad / 2), 0.0)


def _quat_about_x(angle_rad: float) -> tuple[float, float, float, float]:
    return (math.cos(angle_rad / 2), math.sin(angle_rad / 2), 0.0, 0.0)


def _quat_to_matrix(q: tuple[float, float, float, float]) -> np.ndarray:
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _ground_box(cx, cy, hx, hy, top, tile) -> Box:
    """An axis-aligned box from the floor (z = 0) up to ``top`` [m]."""
    return Box((cx, cy, top / 2), (hx, hy, top / 2), (1.0, 0.0, 0.0, 0.0), tile)


def _slab(cx, cy, x0, z0, x1, z1, half_y, thickness, axis: str, tile) -> list[Box]:
    """A tilted slab whose top face runs from (x0, z0) to (x1, z1) along ``axis`` ('x' or 'y',
    coordinates relative to the tile centre ``cx, cy``) and spans +- ``half_y`` across it."""
    if x1 < x0:  # run along +axis so the top-face normal below points up
        x0, z0, x1, z1 = x1, z1, x0, z0
    dx, dz = x1 - x0, z1 - z0
    length = math.hypot(dx, dz)
    if length < 1e-9:
        return []
    angle = math.atan2(dz, dx)  # rise of the top face along +axis
    # Top-face normal in the (axis, z) plane, pointing up.
    nx, nz = -math.sin(angle), math.cos(angle)
    mx, mz = (x0 + x1) / 2 - nx * thickness / 2, (z0 + z1) / 2 - nz * thickness / 2
    if axis == "x":
        return [
            Box(
                (cx + mx, cy, mz),
                (length / 2, half_y, thickness / 2),
                _quat_about_y(-angle),
                tile,
            )
        ]
    return [
        Box(
            (cx, cy + mx, mz),
            (half_y, length / 2, thickness / 2),
            _quat_about_x(angle),
            tile,
        )
    ]


def tile_boxes(
    cfg: TerrainConfig, kind: str, row: int, col: int, cx: float, cy: float, rng
) -> list[Box]:
    """The boxes of one tile of type ``kind`` at level ``row``, centred at (cx, cy) [m]."""
    half, p, tile = cfg.tile_size_m / 2, cfg.platform_half_m, (row, col)
    d = cfg.difficulty(row)
    boxes: list[Box] = []
    if kind == "flat":
        return boxes
    if kind in ("slope_up", "slope_down"):
        s = cfg.slope(row)
        height = s * (half - p)
        if height < 1e-4:
            return boxes
        t = cfg.slab_thickness_m
        if kind == "slope_up":  # pit: four planes z = s (|u| - p), union = max of the planes
            for axis in ("x", "y"):
                for sign in (1.0, -1.0):
                    boxes += _slab(cx, cy, sign * p, 0.0, sign * half, height, half, t, axis, tile)
        else:  # ridge along y: top over |x| <= p, down to the floor at |x| = half
            boxes.append(_ground_box(cx, cy, p, half, height, tile))
            for sign in (1.0, -1.0):
                # Thick enough to reach below the floor over its whole footprint (no void).
                thick = height / math.cos(math.atan(s)) + t
                boxes += _slab(cx, cy, sign * p, height, sign * half, 0.0, half, thick, "x", tile)
        return boxes
    if kind == "rough":
        low, high = cfg.rough_height_range_m
        h_max = low + (high - low) * d
        n = max(1, int(round(cfg.tile_size_m / cfg.rough_cell_m)))
        cell = cfg.tile_size_m / n
        heights = rng.uniform(0.0, h_max, size=(n, n))
        for i in range(n):
            for j in range(n):
                if heights[i, j] < 0.005:
                    continue
                x = cx - half + (i + 0.5) * cell
                y = cy - half + (j + 0.5) * cell
                boxes.append(_ground_box(x, y, cell / 2, cell / 2, float(heights[i, j]), tile))
        return boxes
    if kind == "obstacles":
        low, high = cfg.obstacle_height_range_m
        h_max = low + (high - low) * d
        s_low, s_high = cfg.obstacle_size_range_m
        placed = 0
        while placed < cfg.obstacle_count:
            size = rng.uniform(s_low, s_high, size=2)
            x, y = rng.uniform(-half + size / 2, half - size / 2)
            # Keep the spawn platform free.
            if abs(x) < p + size[0] / 2 and abs(y) < p + size[1] / 2:
                continue
            h = float(rng.uniform(0.5 * h_max, h_max))
            boxes.append(_ground_box(cx + x, cy + y, size[0] / 2, size[1] / 2, h, tile))
            placed += 1
        return boxes
    h = cfg.stair_height_m(row)
    w = cfg.stair_width_m
    steps = int((half - p) // w)
    if kind == "stairs_up":  # rings k = 0.. outward, ring k between a_k and a_k + w at (k+1) h
        for k in range(steps):
            a0, a1 = p + k * w, p + (k + 1) * w
            top, m = (k + 1) * h, (a0 + a1) / 2
            for sign in (1.0, -1.0):
                boxes.append(_ground_box(cx + sign * m, cy, w / 2, a1, top, tile))
                boxes.append(_ground_box(cx, cy + sign * m, a0, w / 2, top, tile))
        return boxes
    if kind == "stairs_down":  # nested boxes, the largest lowest; the platform on top
        # Tread edges at p + k w as for stairs_up; the lowest box fills the tile.
        for k in range(steps + 1):
            a = half if k == 0 else p + (steps - k) * w
            boxes.append(_ground_box(cx, cy, a, a, (k + 1) * h, tile))
        return boxes
    raise ValueError(f"unknown tile type '{kind}'; known: {TILE_TYPES}")


class HeightMap:
    """Terrain height on a regular grid, as a torch tensor, with batched lookup.

    ``heights[i, j]`` is the top of the terrain at x = x0 + i res, y = y0 + j res (0: the floor).
    A lookup reads a copy of the grid on the points' device, made once per device.
    """

    def __init__(self, heights: torch.Tensor, origin_xy_m: tuple[float, float], res_m: float):
        self.heights = heights  # (X, Y) float32 [m]
        self.origin_xy_m = origin_xy_m  # world x, y of cell (0, 0) [m]
        self.res_m = res_m  # cell size [m]
        self._on_device: dict[torch.device, torch.Tensor] = {heights.device: heights}

    def __call__(self, xy_w: torch.Tensor) -> torch.Tensor:
        """Height [m] at world points ``xy_w`` (..., 2), nearest cell; 0 outside the map."""
        ix = torch.round((xy_w[..., 0] - self.origin_xy_m[0]) / self.res_m).long()
        iy = torch.round((xy_w[..., 1] - self.origin_xy_m[1]) / self.res_m).long()
        nx, ny = self.heights.shape
        inside = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny)
        if xy_w.device not in self._on_device:
            self._on_device[xy_w.device] = self.heights.to(xy_w.device)
        heights = self._on_device[xy_w.device]
        h = heights[ix.clamp(0, nx - 1), iy.clamp(0, ny - 1)]
        return torch.where(inside, h, torch.zeros_like(h))

    def __repr__(self) -> str:
        nx, ny = self.heights.shape
        return f"HeightMap({nx}x{ny} cells of {self.res_m} m at {self.origin_xy_m})"


def rasterize(boxes: list[Box], origin_xy: tuple[float, float], shape, res: float) -> np.ndarray:
    """Top surface height (X, Y) [m] of the union of ``boxes`` seen from above (vertical ray
    against each oriented box, slab method), floor 0 elsewhere."""
    heights = np.zeros(shape)
    x_axis = origin_xy[0] + res * np.arange(shape[0])
    y_axis = origin_xy[1] + res * np.arange(shape[1])
    z_top = 100.0
    for box in boxes:
        rot = _quat_to_matrix(box.quat)
        c, h = np.asarray(box.pos), np.asarray(box.half)
        reach = np.abs(rot) @ h  # half extents of the world AABB
        ix = np.flatnonzero(np.abs(x_axis - c[0]) <= reach[0])
        iy = np.flatnonzero(np.abs(y_axis - c[1]) <= reach[1])
        if ix.size == 0 or iy.size == 0:
            continue
        gx, gy = np.meshgrid(x_axis[ix], y_axis[iy], indexing="ij")
        origin = np.stack([gx - c[0], gy - c[1], np.full_like(gx, z_top - c[2])], axis=-1)
        o = origin @ rot  # into the box frame: R^T (p - c) for row vectors
        d = -rot[2]  # R^T (0, 0, -1)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = np.where(np.abs(d) > 1e-12, 1.0 / d, np.inf)
            t1 = (-h - o) * inv
            t2 = (h - o) * inv
        # Axes the ray is parallel to: inside the slab (t in (-inf, inf)) or never.
        parallel = np.abs(d) <= 1e-12
        inside = np.abs(o) <= h
        t_near = np.where(parallel, np.where(inside, -np.inf, np.inf), np.minimum(t1, t2))
        t_far = np.where(parallel, np.where(inside, np.inf, -np.inf), np.maximum(t1, t2))
        enter, leave = t_near.max(axis=-1), t_far.min(axis=-1)
        hit = (enter <= leave) & (leave >= 0)
        top = np.where(hit, z_top - enter, 0.0)
        sub = heights[np.ix_(ix, iy)]
        heights[np.ix_(ix, iy)] = np.maximum(sub, top)
    return heights


class Terrain:
    """The built terrain: its boxes, height map, tile centres and spawn heights.

    Built lazily on first use (importing the task registry stays fast); one instance is shared by
    the scene hook, the curriculum's spawn placement and the height-scan term.
    """

    def __init__(self, cfg: TerrainConfig = TerrainConfig()) -> None:
        self.cfg = cfg
        self._boxes: list[Box] | None = None
        self._height_map: HeightMap | None = None
        self._spawn_height: torch.Tensor | None = None

    # A Terrain is an immutable description: configs holding it share it (no deep copies).
    def __deepcopy__(self, memo: dict[int, Any]) -> Terrain:
        return self

    def __repr__(self) -> str:
        return f"Terrain({self.cfg})"

    @property
    def num_rows(self) -> int:
        """Number of levels."""
        return self.cfg.num_rows

    @property
    def num_cols(self) -> int:
        """Number of tiles per level."""
        return self.cfg.num_cols

    def tile_type(self, col: int) -> str:
        """Type of the tiles of column ``col``."""
        return self.cfg.types[col % len(self.cfg.types)]

    def tile_center_xy(self, row: torch.Tensor, col: torch.Tensor) -> torch.Tensor:
        """World x, y [m] (M, 2) of the centres of tiles (row (M,), col (M,))."""
        size = self.cfg.tile_size_m
        x = (row.float() + 0.5 - self.cfg.num_rows / 2) * size
        y = (col.float() + 0.5 - self.cfg.num_cols / 2) * size
        return torch.stack([x, y], dim=-1)

    @property
    def boxes(self) -> list[Box]:
        """All terrain boxes (built on first access)."""
        if self._boxes is None:
            rng = np.random.default_rng(self.cfg.seed)
            boxes: list[Box] = []
            for row in range(self.cfg.num_rows):
                for col in range(self.cfg.num_cols):
                    cx, cy = self.tile_center_xy(torch.tensor([row]), torch.tensor([col]))[0]
                    kind = self.tile_type(col)
                    boxes += tile_boxes(self.cfg, kind, row, col, float(cx), float(cy), rng)
            self._boxes = boxes
        return self._boxes

    @property
    def height_map(self) -> HeightMap:
        """The rasterised height map (built on first access)."""
        if self._height_map is None:
            cfg = self.cfg
            res = cfg.height_map_resolution_m
            ext_x = cfg.num_rows * cfg.tile_size_m / 2 + cfg.margin_m
            ext_y = cfg.num_cols * cfg.tile_size_m / 2 + cfg.margin_m
            shape = (int(round(2 * ext_x / res)) + 1, int(round(2 * ext_y / res)) + 1)
            heights = rasterize(self.boxes, (-ext_x, -ext_y), shape, res)
            self._height_map = HeightMap(
                torch.as_tensor(heights, dtype=torch.float32), (-ext_x, -ext_y), res
            )
        return self._height_map

    @property
    def spawn_height_m(self) -> torch.Tensor:
        """(rows, cols) highest terrain point within 0.3 m of each tile centre [m]."""
        if self._spawn_height is None:
            rows, cols = torch.meshgrid(
                torch.arange(self.num_rows), torch.arange(self.num_cols), indexing="ij"
            )
            centre = self.tile_center_xy(rows.flatten(), cols.flatten())
            offsets = torch.linspace(-0.3, 0.3, 7)
            ox, oy = torch.meshgrid(offsets, offsets, indexing="ij")
            points = centre[:, None, :] + torch.stack([ox.flatten(), oy.flatten()], -1)[None]
            self._spawn_height = self.height_map(points).amax(dim=-1).reshape(rows.shape)
        return self._spawn_height

    def add_to_spec(self, spec: mujoco.MjSpec) -> None:
        """The ``SceneConfig.terrain`` hook: add every box to the world body (contype 1,
        conaffinity 3, like the floor; friction is randomised with the floor's)."""
        world = spec.worldbody
        for k, box in enumerate(self.boxes):
            shade = 0.35 + 0.4 * box.tile[0] / max(self.num_rows - 1, 1)
            world.add_geom(
                name=f"terrain_{k}",
                type=mujoco.mjtGeom.mjGEOM_BOX,
                size=list(box.half),
                pos=list(box.pos),
                quat=list(box.quat),
                contype=1,
                conaffinity=3,
                condim=3,
                friction=[1.0, 0.005, 0.0001],
                rgba=[shade, 0.45, 0.35, 1.0],
            )

    def __call__(self, spec: mujoco.MjSpec) -> None:
        """Same as :meth:`add_to_spec` (a Terrain is itself a ``TerrainFn``)."""
        self.add_to_spec(spec)
