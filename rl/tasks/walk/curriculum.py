"""The walk's terrain and its terrain curriculum, which is the task's skill measure.

Robots start in the centre of a tile of their terrain level (:mod:`rl.tasks.terrain`: flat, slopes,
rough, obstacles, stairs, 10 levels, top stair 0.23 m); at the end of an episode a robot that
walked off its tile (more than half a tile from its start) is promoted, one that walked less than
half its commanded distance demoted, and a robot promoted past the top level is sent to a random
level (Isaac Lab's terrain curriculum; the paper's mean level then settles near 6). Skill progress
= mean level over ``learned_fraction`` of the top level.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import torch

from rl.envs.components import SkillMeasure
from rl.envs.state import EnvState
from rl.tasks.terrain import Terrain, TerrainConfig

WALK_TERRAIN = Terrain(TerrainConfig())
"""The walk task's terrain (built on first use), shared by scene, curriculum and height scan."""


@dataclass(frozen=True)
class TerrainCurriculumConfig:
    """Terrain-level curriculum and the walk skill measure (see the module docstring)."""

    terrain: Terrain = WALK_TERRAIN  # the terrain the envs are placed on
    max_init_level: int = 0  # first levels are drawn uniformly in [0, max_init_level] [-]
    promote_tile_fraction: float = 0.5  # promote when the distance walked exceeds this x tile [-]
    demote_command_fraction: float = 0.5  # demote below this x commanded distance [-]
    learned_fraction: float = 0.6  # skill learned at mean level = this x top level [-]
    seed: int = 0  # generator of the random levels of top-level solvers [-]

    def __post_init__(self) -> None:
        if not 0 <= self.max_init_level < self.terrain.num_rows:
            raise ValueError(
                f"terrain curriculum max_init_level must be in [0, {self.terrain.num_rows - 1}], "
                f"got {self.max_init_level}"
            )
        if not 0.0 < self.learned_fraction <= 1.0:
            raise ValueError(
                f"terrain curriculum learned_fraction must be in (0, 1], got {self.learned_fraction}"
            )

    def build(self, max_episode_length: int) -> TerrainCurriculum:
        """The live curriculum for episodes of ``max_episode_length`` policy steps."""
        return TerrainCurriculum(self, max_episode_length)


class TerrainCurriculum(SkillMeasure):
    """Per-env terrain level and tile; places resetting robots on their tile (``reset_state``)
    and moves levels at episode ends. Per-env tensors are sized at the env's first reset (which
    resets every env), as the build hook does not receive the number of envs. They live in host
    memory with the terrain grid and the curriculum's own generator: on a GPU env the rows of
    resetting and finishing envs cross to the host there (never in the rest of a step)."""

    def __init__(self, cfg: TerrainCurriculumConfig, max_episode_length: int) -> None:
        self.cfg = cfg
        self.terrain = cfg.terrain
        self.max_episode_length = max_episode_length
        self.top_level = cfg.terrain.num_rows - 1
        self.levels = torch.zeros(0, dtype=torch.long)  # (N,) terrain level (row) [-]
        self.cols = torch.zeros(0, dtype=torch.long)  # (N,) tile column of this episode [-]
        self.spawn_xy_w = torch.zeros(0, 2)  # (N, 2) start position of this episode [m]
        self.placed = torch.zeros(0, dtype=torch.bool)  # (N,) level drawn already
        self.fixed_tiles: torch.Tensor | None = None  # (N, 2) (row, col) pinned (evaluation)
        self.generator = torch.Generator().manual_seed(cfg.seed)
        self.promotions = 0
        self.demotions = 0

    def _ensure(self, size: int) -> None:
        grow = size - self.levels.numel()
        if grow > 0:
            self.levels = torch.cat([self.levels, torch.zeros(grow, dtype=torch.long)])
            self.cols = torch.cat([self.cols, torch.zeros(grow, dtype=torch.long)])
            self.spawn_xy_w = torch.cat([self.spawn_xy_w, torch.zeros(grow, 2)])
            self.placed = torch.cat([self.placed, torch.zeros(grow, dtype=torch.bool)])

    def pin_tiles(self, tiles: torch.Tensor | None) -> None:
        """Pin env i to tile ``tiles[i]`` = (row, col) at its next resets (None: unpin)."""
        self.fixed_tiles = None if tiles is None else tiles.long().cpu().clone()

    def reset_state(
        self,
        env_ids: torch.Tensor,
        qpos: torch.Tensor,
        qvel: torch.Tensor,
        generator: torch.Generator,
    ) -> None:
        """Move resetting robots to the centre of a tile of their level (random column),
        raised by the tile's spawn height."""
        env_ids, dev = env_ids.cpu(), generator.device  # draws on the env's generator's device
        self._ensure(int(env_ids.max()) + 1)
        m = env_ids.numel()
        new = env_ids[~self.placed[env_ids]]
        if new.numel():
            high = self.cfg.max_init_level + 1
            draw = torch.randint(0, high, (new.numel(),), generator=generator, device=dev)
            self.levels[new] = draw.cpu()
            self.placed[new] = True
        cols = torch.randint(0, self.terrain.num_cols, (m,), generator=generator, device=dev)
        self.cols[env_ids] = cols.cpu()
        if self.fixed_tiles is not None:
            self.levels[env_ids] = self.fixed_tiles[env_ids, 0]
            self.cols[env_ids] = self.fixed_tiles[env_ids, 1]
        rows, cols = self.levels[env_ids], self.cols[env_ids]
        centre = self.terrain.tile_center_xy(rows, cols)
        qpos[:, 0:2] = centre.double().to(qpos.device)
        qpos[:, 2] += self.terrain.spawn_height_m[rows, cols].double().to(qpos.device)
        self.spawn_xy_w[env_ids] = centre

    def distance_walked_m(self, env_ids: torch.Tensor, state: EnvState) -> torch.Tensor:
        """Horizontal distance (M,) [m] of ``env_ids`` from their episode's start (on the host)."""
        start_xy = self.spawn_xy_w[env_ids.cpu()]
        return (state.base_pos_w[env_ids, :2].cpu() - start_xy).norm(dim=-1)

    def update_levels(
        self, env_ids: torch.Tensor, distance_m: torch.Tensor, required_m: torch.Tensor
    ) -> None:
        """Promote ``env_ids`` (M,) that walked more than the promotion distance, demote those
        that walked less than ``required_m`` (M,) [m]; past the top: a random level."""
        promote = distance_m > self.cfg.promote_tile_fraction * self.terrain.cfg.tile_size_m
        demote = (distance_m < required_m) & ~promote
        levels = self.levels[env_ids] + promote.long() - demote.long()
        solved = levels > self.top_level
        random_levels = torch.randint(
            0, self.top_level + 1, (env_ids.numel(),), generator=self.generator
        )
        self.levels[env_ids] = torch.where(solved, random_levels, levels.clamp_min(0))
        self.promotions += int(promote.sum())
        self.demotions += int(demote.sum())

    def on_episodes_end(
        self,
        env_ids: torch.Tensor,
        time_outs: torch.Tensor,
        lived_steps: torch.Tensor,
        state: EnvState,
    ) -> None:
        """Move the levels of finished episodes: commanded distance = |v_xy^cmd| x the episode
        duration (the lived time for time-outs, the full episode for falls)."""
        distance = self.distance_walked_m(env_ids, state)
        steps = torch.where(
            time_outs, lived_steps, torch.full_like(lived_steps, self.max_episode_length)
        )
        duration_s = steps.float() * state.step_dt_s
        required = (
            self.cfg.demote_command_fraction * state.command[env_ids, :2].norm(dim=-1) * duration_s
        )
        self.update_levels(env_ids.cpu(), distance, required.cpu())

    def alone_measure(self) -> AloneTerrainLevels:
        """The alone envs' measure: their levels in this curriculum (which places every env)."""
        return AloneTerrainLevels(self)

    def mean_level(self) -> float:
        """Mean terrain level of the envs [-]."""
        return float(self.levels.float().mean()) if self.levels.numel() else 0.0

    def progress(self) -> float:
        """Mean level over ``learned_fraction`` x top level."""
        return self.mean_level() / (self.cfg.learned_fraction * self.top_level)

    def log(self) -> dict[str, float]:
        """``Curriculum/terrain_level`` (mean), its max and the share of envs per level."""
        if not self.levels.numel():
            return {}
        counts = torch.bincount(self.levels, minlength=self.top_level + 1).float()
        share = counts / self.levels.numel()
        out = {
            "Curriculum/terrain_level": self.mean_level(),
            "Curriculum/terrain_level_max": float(self.levels.max()),
        }
        for level, value in enumerate(share.tolist()):
            out[f"Curriculum/terrain_level_share_{level}"] = value
        return out

    def state_dict(self) -> dict[str, Any]:
        """Levels, tiles, starts and the generator."""
        return {
            "levels": self.levels.clone(),
            "cols": self.cols.clone(),
            "spawn_xy_w": self.spawn_xy_w.clone(),
            "placed": self.placed.clone(),
            "generator": self.generator.get_state(),
            "promotions": self.promotions,
            "demotions": self.demotions,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` output."""
        self.levels = state["levels"].clone()
        self.cols = state["cols"].clone()
        self.spawn_xy_w = state["spawn_xy_w"].clone()
        self.placed = state["placed"].clone()
        self.generator.set_state(state["generator"])
        self.promotions = int(state["promotions"])
        self.demotions = int(state["demotions"])


class AloneTerrainLevels(SkillMeasure):
    """The alone envs' terrain curriculum (A2CF's envs that are never helped): their episodes move
    their own levels in the walk's curriculum, which places every env at its resets (so the tiles,
    starts and levels stay one per env); progress = the mean level of the envs seen here over
    ``learned_fraction`` x top level."""

    def __init__(self, curriculum: TerrainCurriculum) -> None:
        self.curriculum = curriculum
        self.seen = torch.zeros(0, dtype=torch.bool)  # (N,) envs whose episodes came here

    def on_episodes_end(
        self,
        env_ids: torch.Tensor,
        time_outs: torch.Tensor,
        lived_steps: torch.Tensor,
        state: EnvState,
    ) -> None:
        """Move the finished alone episodes' levels; remember which envs are alone."""
        self.curriculum.on_episodes_end(env_ids, time_outs, lived_steps, state)
        ids = env_ids.cpu()
        grow = int(ids.max()) + 1 - self.seen.numel()
        if grow > 0:
            self.seen = torch.cat([self.seen, torch.zeros(grow, dtype=torch.bool)])
        self.seen[ids] = True

    def mean_level(self) -> float:
        """Mean terrain level of the alone envs seen so far [-] (0 before any)."""
        levels = self.curriculum.levels[: self.seen.numel()][self.seen]
        return float(levels.float().mean()) if levels.numel() else 0.0

    def progress(self) -> float:
        """The alone envs' mean level over ``learned_fraction`` x top level."""
        cfg = self.curriculum.cfg
        return self.mean_level() / (cfg.learned_fraction * self.curriculum.top_level)

    def log(self) -> dict[str, float]:
        """``Curriculum/terrain_level_alone``, once an alone episode has ended."""
        return {"Curriculum/terrain_level_alone": self.mean_level()} if self.seen.any() else {}

    def state_dict(self) -> dict[str, Any]:
        """Which envs are alone (their levels live in the curriculum's state)."""
        return {"seen": self.seen.clone()}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` output."""
        self.seen = state["seen"].clone()
