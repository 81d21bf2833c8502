"""The walk task: terrain geometry, height scan, terrain curriculum, reward terms, training, eval
and compare on tiny runs."""

from __future__ import annotations

import dataclasses
import json
import math

import mujoco
import numpy as np
import pytest
import torch
from test_rewards import random_state
from test_training import tiny_config

from a2cf_mb.cli import main as cli_main
from rl.evaluation.policy import EvalConfig, evaluate
from rl.tasks.terrain import HeightMap, Terrain, TerrainConfig, tile_boxes
from rl.tasks.walk import terms as walk_terms
from rl.tasks.walk.command import VelocityCommandConfig
from rl.tasks.walk.curriculum import TerrainCurriculumConfig
from rl.tasks.walk.task import WALK, WALK_FLAT, WALK_PAPER
from rl.training.runner import train

SMALL = TerrainConfig(num_rows=3, num_cols=7, tile_size_m=3.0, rough_cell_m=0.5, obstacle_count=4)
"""Every tile type at three levels, small tiles (fast to build and ray cast)."""


# ------------------------------------------------------------------------------ terrain
def test_stair_heights_per_level() -> None:
    cfg = TerrainConfig()
    assert cfg.stair_height_m(0) == pytest.approx(0.05)
    assert cfg.stair_height_m(cfg.num_rows - 1) == pytest.approx(0.23)
    terrain = Terrain(cfg)
    hm = terrain.height_map
    col_down = cfg.types.index("stairs_down")
    col_up = cfg.types.index("stairs_up")
    steps = int((cfg.tile_size_m / 2 - cfg.platform_half_m) // cfg.stair_width_m)
    for row in range(cfg.num_rows):
        h = cfg.stair_height_m(row)
        boxes = tile_boxes(cfg, "stairs_down", row, col_down, 0.0, 0.0, None)
        tops = sorted(2 * b.half[2] for b in boxes)
        assert np.allclose(np.diff(tops), h), row
        # Walking out of the centre along +x: the height map goes down (or up) one riser a tread.
        for col, sign in ((col_down, -1.0), (col_up, 1.0)):
            centre = terrain.tile_center_xy(torch.tensor([row]), torch.tensor([col]))[0]
            u = cfg.platform_half_m + (torch.arange(steps) + 0.5) * cfg.stair_width_m
            points = torch.stack([centre[0] + u, centre[1].expand(steps)], dim=-1)
            heights = hm(points)
            assert torch.allclose(heights.diff(), torch.tensor(sign * h), atol=1e-5), (row, col)
        top = terrain.spawn_height_m[row, col_down]
        assert float(top) == pytest.approx((steps + 1) * h, abs=1e-5)
    assert float(terrain.spawn_height_m[:, col_up].abs().max()) == 0.0  # pits start at the floor


def test_height_map_matches_mujoco_ray_cast() -> None:
    terrain = Terrain(SMALL)
    spec = mujoco.MjSpec()
    terrain.add_to_spec(spec)
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    hm = terrain.height_map
    rng = np.random.default_rng(0)
    geom = np.zeros(1, dtype=np.int32)
    idx = rng.integers(0, hm.heights.shape, size=(1500, 2))
    errors = []
    for i, j in idx:
        x = hm.origin_xy_m[0] + i * hm.res_m
        y = hm.origin_xy_m[1] + j * hm.res_m
        dist = mujoco.mj_ray(
            model, data, np.array([x, y, 10.0]), np.array([0, 0, -1.0]), None, 1, -1, geom
        )
        ray_height = 10.0 - dist if dist >= 0 else 0.0
        errors.append(abs(ray_height - float(hm.heights[i, j])))
    assert max(errors) < 1e-4
    assert float(hm.heights.max()) > 0.2  # the test saw real geometry, not only floor


def test_terrain_geom_count_stays_moderate() -> None:
    assert len(Terrain().boxes) < 2000


def _scan_state(pos, yaw: float) -> object:
    s = random_state()
    n = s.base_pos_w.shape[0]
    quat = torch.tensor([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]).expand(n, 4)
    return dataclasses.replace(s, base_pos_w=torch.tensor(pos).expand(n, 3), base_quat_w=quat)


def test_height_scan_against_a_known_step() -> None:
    # A 0.3 m step up for x >= 0 (cells of 0.05 m from x = -5 m).
    res, origin = 0.05, (-5.0, -5.0)
    x = origin[0] + res * torch.arange(201)
    heights = (x >= -1e-6).float()[:, None].expand(201, 201) * 0.3
    hm = HeightMap(heights.contiguous(), origin, res)
    offsets = walk_terms.scan_offsets_b((1.6, 1.0), 0.1)
    assert offsets.shape == (17 * 11, 2)
    # Pelvis at x = -0.35 m facing +x: points with x_b >= 0.35 see the step.
    s = _scan_state([-0.35, 0.0, 0.8], 0.0)
    scan = walk_terms.height_scan(s, hm, size_m=(1.6, 1.0), resolution_m=0.1)[0]
    expected = torch.where(offsets[:, 0] >= 0.35 - 1e-6, 0.8 - 0.3 - 0.5, 0.8 - 0.5)
    assert torch.allclose(scan, expected, atol=1e-5)
    # Turned by +90 deg: body +y points to world -x, so points with y_b <= -0.35 see the step.
    s = _scan_state([-0.35, 0.0, 0.8], math.pi / 2)
    scan = walk_terms.height_scan(s, hm, size_m=(1.6, 1.0), resolution_m=0.1)[0]
    expected = torch.where(offsets[:, 1] <= -0.35 + 1e-6, 0.0, 0.3)
    assert torch.allclose(scan, expected, atol=1e-5)


# ------------------------------------------------------------------------ curriculum
def _curriculum(terrain: Terrain, **changes):
    cfg = dataclasses.replace(TerrainCurriculumConfig(terrain=terrain), **changes)
    return cfg.build(max_episode_length=1000)


def test_spawn_on_tiles_of_the_level() -> None:
    terrain = Terrain(SMALL)
    cur = _curriculum(terrain, max_init_level=2)
    ids = torch.arange(64)
    qpos = torch.zeros(64, 36, dtype=torch.float64)
    qpos[:, 2] = 0.79
    cur.reset_state(ids, qpos, torch.zeros(64, 35, dtype=torch.float64), torch.Generator())
    centre = terrain.tile_center_xy(cur.levels, cur.cols)
    assert torch.allclose(qpos[:, :2].float(), centre)
    expected_z = 0.79 + terrain.spawn_height_m[cur.levels, cur.cols]
    assert torch.allclose(qpos[:, 2].float(), expected_z)
    assert set(cur.levels.tolist()) <= {0, 1, 2} and len(set(cur.cols.tolist())) > 3


def test_promotion_and_demotion_on_scripted_distances() -> None:
    terrain = Terrain(SMALL)  # 3 levels, tile 3 m: promotion beyond 1.5 m
    cur = _curriculum(terrain)
    ids = torch.arange(5)
    cur.reset_state(
        ids, torch.zeros(5, 36, dtype=torch.float64), torch.zeros(5, 35, dtype=torch.float64),
        torch.Generator(),
    )  # fmt: skip
    cur.levels[:] = torch.tensor([0, 1, 2, 1, 0])
    walked = torch.tensor([[2.0, 0.0], [0.5, 0.0], [0.0, 1.6], [1.2, 0.0], [0.2, 0.0]])
    command = torch.tensor([[1.0, 0, 0], [1.0, 0, 0], [1.0, 0, 0], [0.1, 0, 0], [0.5, 0, 0]])
    s = dataclasses.replace(
        random_state(), base_pos_w=torch.cat([cur.spawn_xy_w + walked, torch.ones(5, 1)], -1)
    )
    s = dataclasses.replace(s, command=command, step_dt_s=0.02)
    time_outs = torch.tensor([True, True, True, True, False])
    lived = torch.tensor([1000, 1000, 1000, 1000, 10])
    cur.on_episodes_end(ids, time_outs, lived, s)
    # 0: 2 m > 1.5 m: up. 1: 0.5 m < 0.5 x 1 m/s x 20 s: down. 2: top level solved: random
    # level. 3: 1.2 m vs 0.5 x 0.1 x 20 = 1 m required: stays. 4: fell after 10 steps, 0.2 m
    # < 0.5 x 0.5 m/s x 20 s (a fall counts the full episode): down, clamped at 0.
    assert cur.levels[[0, 1, 3, 4]].tolist() == [1, 0, 1, 0]
    assert 0 <= int(cur.levels[2]) <= 2
    assert (cur.promotions, cur.demotions) == (2, 2)
    cur.levels[:] = torch.tensor([2, 2, 2, 2, 2])
    assert cur.progress() == pytest.approx(2 / (0.6 * 2))
    assert cur.log()["Curriculum/terrain_level"] == pytest.approx(2.0)
    state = cur.state_dict()
    other = _curriculum(terrain)
    other.load_state_dict(state)
    assert torch.equal(other.levels, cur.levels)


def test_velocity_command_ranges_resampling_and_standing() -> None:
    cfg = VelocityCommandConfig(resampling_time_range_s=(0.1, 0.1), standing_fraction=0.25)
    gen = torch.Generator().manual_seed(0)
    cmd = cfg.build(4000, gen)
    cmd.reset(torch.arange(4000))
    first = cmd.command.clone()
    assert first[:, 0].min() >= -0.6 and first[:, 0].max() <= 1.2
    assert first[:, 1].abs().max() <= 0.8 and first[:, 2].abs().max() <= 1.5
    standing = (first.abs().sum(-1) == 0).float().mean()
    assert 0.2 < float(standing) < 0.3
    cmd.compute(random_state(), 0.05)
    assert torch.equal(cmd.command, first)  # not due yet
    cmd.compute(random_state(), 0.06)
    assert (cmd.command != first).any(dim=-1).float().mean() > 0.7  # resampled within the episode


# ----------------------------------------------------------------------------- rewards
def test_walk_reward_terms_against_hand_values() -> None:
    s = random_state()
    n = s.base_pos_w.shape[0]
    cmd = torch.tensor([0.5, 0.0, 1.0]).expand(n, 3)
    s = dataclasses.replace(
        s,
        command=cmd,
        base_lin_vel_b=torch.tensor([1.0, 0.5, 0.0]).expand(n, 3),
        base_ang_vel_b=torch.tensor([0.0, 0.0, 0.5]).expand(n, 3),
        foot_first_contact=torch.tensor([True, False]).expand(n, 2),
        foot_last_air_time_s=torch.tensor([0.4, 0.3]).expand(n, 2),
    )
    # (1 - 0.5)^2 + 0.5^2 = 0.5 -> exp(-2); (0.5 - 1)^2 = 0.25 -> exp(-1)
    assert torch.allclose(walk_terms.track_lin_vel_xy_exp(s), torch.tensor(math.exp(-2.0)))
    assert torch.allclose(walk_terms.track_ang_vel_z_exp(s), torch.tensor(math.exp(-1.0)))
    assert torch.allclose(walk_terms.feet_air_time(s), torch.tensor(0.4))
    zero_cmd = dataclasses.replace(s, command=torch.zeros(n, 3))
    assert torch.equal(walk_terms.feet_air_time(zero_cmd), torch.zeros(n))
    # stand still: only with |c| < 0.1; |q - q0| (L2 norm)
    q = torch.zeros(n, 29)
    q[:, 0], q[:, 1] = 0.3, 0.4
    still = dataclasses.replace(zero_cmd, joint_pos_rad=q, default_joint_pos_rad=torch.zeros(29))
    assert torch.allclose(walk_terms.stand_still(still), torch.tensor(0.5))
    assert torch.equal(
        walk_terms.stand_still(dataclasses.replace(still, command=cmd)), torch.zeros(n)
    )
    # cost of transport |qdot| |tau| / (9.81 |v_xy|): |qdot| = 5, |tau| = 13, v = 2 m/s
    qd, tau = torch.zeros(n, 29), torch.zeros(n, 29)
    qd[:, 0], qd[:, 1], tau[:, 2], tau[:, 3] = 3.0, 4.0, 5.0, 12.0
    moving = dataclasses.replace(
        s,
        joint_vel_rps=qd,
        joint_torque_nm=tau,
        base_lin_vel_w=torch.tensor([0.0, 2.0, 0.3]).expand(n, 3),
    )
    assert torch.allclose(walk_terms.cost_of_transport(moving), torch.tensor(65.0 / (9.81 * 2.0)))


def test_cost_of_transport_finite_at_zero_speed() -> None:
    s = random_state()
    n = s.base_pos_w.shape[0]
    s = dataclasses.replace(s, base_lin_vel_w=torch.zeros(n, 3))
    cot = walk_terms.cost_of_transport(s, min_speed_mps=0.1)
    assert torch.isfinite(cot).all()
    expected = s.joint_vel_rps.norm(dim=-1) * s.joint_torque_nm.norm(dim=-1) / (9.81 * 0.1)
    assert torch.allclose(cot, expected)


def test_walk_paper_is_the_paper_table_and_walk_the_recipe() -> None:
    weights = {t.name: t.weight for t in WALK_PAPER.rewards}
    assert weights == {
        "track_lin_vel_xy": 5.0, "track_ang_vel_z": 2.0, "feet_air_time": 1.0, "feet_slide": -1.0,
        "cost_of_transport": -0.01, "stand_still": -0.1, "action_rate": -0.01,
        "joint_acc": -2.5e-7, "joint_pos_limits": -1.0, "orientation": -1.0,
    }  # fmt: skip
    recipe = {t.name for t in WALK.rewards}
    assert {"alive", "termination", "gait_contact", "energy", "upper_body_pose"} <= recipe
    assert {t.name for t in WALK_FLAT.rewards} == recipe | {"feet_swing_height"}
    assert WALK.commands.dim == 5 and WALK_PAPER.commands.dim == 3  # gait clock
    assert WALK_FLAT.scene.terrain is None and WALK.scene.terrain is not None
    assert WALK.less_assist_weight == 2.0
    assert "height_scan" in WALK.observations.privileged.names()
    assert "height_scan" in WALK.observations.critic.names()
    assert "height_scan" not in WALK.observations.policy.names()


# --------------------------------------------------------------------- train, eval, compare
@pytest.fixture(scope="module")
def walk_runs(tmp_path_factory):
    """Two iterations of walk in modes baseline and a2cf (tiny sizes)."""
    out = tmp_path_factory.mktemp("walk_runs")
    runs = {}
    for mode in ("baseline", "a2cf"):
        cfg = tiny_config(out, mode, task="walk", run_name=f"walk_{mode}")
        result = train(cfg, verbose=False)
        assert result.iterations_done == 2
        runs[mode] = result.run_dir
    return runs


def test_two_training_iterations_of_walk(walk_runs) -> None:
    for mode, run in walk_runs.items():
        metrics = json.loads((run / "metrics.json").read_text())
        rows = metrics["iterations"]
        assert len(rows) == 2 and all(math.isfinite(r["mean_step_reward"]) for r in rows)
        assert (rows[-1]["applied_force_n"] > 0.0) == (mode == "a2cf")


def test_walk_eval_and_compare(walk_runs, tmp_path) -> None:
    run = walk_runs["a2cf"]
    result = evaluate(run, EvalConfig(num_envs=8, num_steps=15))
    table = result["task_metrics"]["per_terrain_level"]
    # 8 envs over 7 columns: every terrain type at level 0, one at level 3.
    assert {r["terrain"] for r in table} == set(WALK.skill.terrain.cfg.types)
    assert {(r["terrain"], r["level"]) for r in table if r["level"] == 3} == {("flat", 3)}
    assert all(0.0 <= r["survival"] <= 1.0 and r["lin_vel_error_mps"] >= 0 for r in table)
    assert (run / "walk_eval.json").is_file() and (run / "walk_eval.png").is_file()
    code = cli_main(
        [
            "compare",
            str(walk_runs["baseline"]),
            str(run),
            "--out",
            str(tmp_path),
            "--levels",
            "0",
            "5",
        ]
    )
    assert code == 0 and (tmp_path / "compare.png").is_file()
    cmp = json.loads((tmp_path / "compare.json").read_text())
    rows = {r["mode"]: r for r in cmp["runs"]}
    assert rows["a2cf"]["to_level"]["0.0"]["iterations"] == 0.0  # level 0 from the start
    assert rows["a2cf"]["to_level"]["5.0"]["iterations"] is None
    assert rows["a2cf"]["eval_lin_vel_error_mps"] == result["task_metrics"]["lin_vel_error_mps"]
    assert rows["baseline"]["to_negligible_force"] is None
    assert 0.0 <= rows["a2cf"]["final_raw_track_lin_vel_xy"] <= 1.0
    scripted = evaluate(run, EvalConfig(num_envs=2, num_steps=5, scripted=True))
    assert scripted["task_metrics"]["command_script"] == [
        "forward", "backward", "sideways", "turn", "stop"
    ]  # fmt: skip


# ------------------------------------------------------------------------------ per command
def test_scripted_commands_and_the_standing_still_bar(tmp_path) -> None:
    """A scripted sequence drives every env by its episode time; the per-command table holds
    one row per segment, and a robot that holds its pose scores about the standing-still bar
    (the error it would make by not moving), so the table fails a robot that does not walk."""
    from rl.envs.task_schema import quiet
    from rl.tasks.registry import make_env
    from rl.tasks.walk.command import CommandSegment
    from rl.tasks.walk.evaluation import COMMAND_KINDS, WalkEvaluationConfig, command_kind

    script = (
        CommandSegment("forward", 0.2, (0.8, 0.0, 0.0)),
        CommandSegment("turn", 0.2, (0.0, 0.0, 0.8)),
        CommandSegment("stop", 0.2, (0.0, 0.0, 0.0)),
    )
    from rl.evaluation.policy import _VideoFrames

    env = make_env(quiet(WALK_FLAT), 3, num_threads=1)
    evaluator = WalkEvaluationConfig(command_script=script).build(env)
    active = torch.ones(3, dtype=torch.bool)
    seen, video = [], _VideoFrames()
    for _ in range(40):  # 0.8 s: the last segment is held
        _, _, dones, extras = env.step(torch.zeros(3, env.num_actions))
        seen.append(env.env_state.command[:, :3].clone())
        evaluator.on_step(env, active, dones, extras)
        active &= ~dones.bool()
        video.record(env)
    # a video's caption: env 0's command of each frame, with the robot's own pelvis velocity
    assert video.captions[2].startswith("command: vx +0.80 m/s  vy +0.00 m/s  yaw +0.00 rad/s")
    assert video.captions[14].startswith("command: vx +0.00 m/s  vy +0.00 m/s  yaw +0.80 rad/s")
    assert (
        all("\nrobot (0.5 s mean): vx " in c for c in video.captions) and len(video.captions) == 40
    )
    assert torch.allclose(seen[2][0], torch.tensor([0.8, 0.0, 0.0]))
    assert torch.allclose(seen[14][1], torch.tensor([0.0, 0.0, 0.8]))
    assert torch.allclose(seen[-1][2], torch.zeros(3))
    result = evaluator.finish(tmp_path)
    rows = {r["command"]: r for r in result["per_command"]}
    assert list(rows) == ["forward", "turn", "stop"] and result["command_script"] == list(rows)
    assert rows["forward"]["standing_still_lin_vel_error_mps"] == pytest.approx(0.8)
    assert rows["turn"]["standing_still_yaw_rate_error_rps"] == pytest.approx(0.8)
    assert rows["stop"]["standing_still_lin_vel_error_mps"] == 0.0
    # a robot holding its pose makes about the standing-still error where it is told to walk
    assert rows["forward"]["lin_vel_error_mps"] == pytest.approx(0.8, abs=0.2)
    assert json.loads((tmp_path / "walk_eval.json").read_text())["per_command"][0]["steps"] > 0
    # random draws are binned by what they mostly ask for
    kinds = command_kind(torch.tensor([[0.0, 0, 0], [0.5, 0, 0], [-0.4, 0.1, 0], [0.1, 0.3, 0.2],
                                       [0.2, 0.0, -0.9]]))  # fmt: skip
    assert [COMMAND_KINDS[k] for k in kinds] == ["stop", "forward", "backward", "sideways", "turn"]


def test_scripted_eval_is_refused_for_a_task_without_commands() -> None:
    from rl.evaluation.policy import _scripted_evaluation
    from rl.tasks.registry import get_task

    with pytest.raises(ValueError, match="'stand' has no scripted command sequence"):
        _scripted_evaluation(get_task("stand"))
    assert _scripted_evaluation(WALK).command_script[0].name == "forward"


# ------------------------------------------------------------------------- judge per command kind
def test_pure_draws_keep_one_axis_and_off_they_change_nothing() -> None:
    """With ``pure_fraction`` 1 every moving draw asks for one thing (forward or back, sideways,
    or turning on the spot); at 0 the draws are those of the generator without the option."""
    from rl.tasks.walk.command import VelocityCommandConfig

    pure = VelocityCommandConfig(pure_fraction=1.0, standing_fraction=0.0)
    gen = pure.build(600, torch.Generator().manual_seed(3))
    gen.resample(torch.arange(600))
    nonzero = (gen.command[:, :3] != 0).sum(-1)
    assert bool((nonzero == 1).all())
    axes = (gen.command[:, :3] != 0).float().mean(0)  # each axis about a third of the draws
    assert bool(((axes > 0.25) & (axes < 0.42)).all())
    plain, off = VelocityCommandConfig(), VelocityCommandConfig(pure_fraction=0.0)
    a = plain.build(50, torch.Generator().manual_seed(5))
    b = off.build(50, torch.Generator().manual_seed(5))
    a.resample(torch.arange(50))
    b.resample(torch.arange(50))
    assert torch.equal(a.command, b.command)
    with pytest.raises(ValueError, match="pure_fraction must be in"):
        VelocityCommandConfig(pure_fraction=1.5)


def test_the_judge_holds_each_kind_and_fails_a_robot_that_stands() -> None:
    """Env i holds a pure command of kind i mod 6 for its episode (mixed envs draw); the score
    is the worst kind's error over half of a robot standing still's, so standing still scores 2
    on every moving kind and a tracker that does what it is told scores 0."""
    from rl.envs.task_schema import quiet
    from rl.tasks.registry import make_env
    from rl.tasks.walk.evaluation import JUDGED_KINDS, command_score

    env = make_env(quiet(WALK_FLAT), 12, num_threads=1)
    evaluator = WALK_FLAT.evaluation.build(env)
    active = torch.ones(12, dtype=torch.bool)
    for _ in range(10):
        _, _, dones, extras = env.step(torch.zeros(12, env.num_actions))
        evaluator.on_step(env, active, dones, extras)
        active &= ~dones.bool()
    held = env.env_state.command[:, :3]
    assert torch.allclose(held[1], torch.tensor([0.8, 0.0, 0.0]))  # forward
    assert torch.allclose(held[2], torch.tensor([-0.4, 0.0, 0.0]))  # backward
    assert torch.allclose(held[3], torch.tensor([0.0, 0.3, 0.0]))  # sideways, left
    assert torch.allclose(held[9], torch.tensor([0.0, -0.3, 0.0]))  # sideways, right
    assert torch.allclose(held[10], torch.tensor([0.0, 0.0, -0.8]))  # turn, clockwise
    assert torch.equal(held[0], torch.zeros(3)) and torch.equal(held[6], torch.zeros(3))
    rows = evaluator.per_command()
    assert [r["command"] for r in rows] == list(JUDGED_KINDS)

    def table(policy_error: float) -> list[dict]:
        out = []
        for r in rows:
            lin, yaw = r["standing_still_lin_vel_error_mps"], r["standing_still_yaw_rate_error_rps"]
            still = r["command"] == "stop"
            out.append(dict(r, lin_vel_error_mps=0.05 if still else policy_error * lin,
                            yaw_rate_error_rps=0.05 if still else policy_error * yaw))  # fmt: skip
        return out

    assert command_score(table(1.0)) == pytest.approx(2.0)  # standing still: twice the bar
    assert command_score(table(0.4)) < 1.0  # within half of standing still on every kind
    # a policy that walks but ignores sideways fails although the others pass
    ignores = [dict(r, lin_vel_error_mps=r["standing_still_lin_vel_error_mps"])
               if r["command"] == "sideways" else r for r in table(0.2)]  # fmt: skip
    assert command_score(ignores) == pytest.approx(2.0)
    # stop is judged by staying still: drifting at the smallest bar (half of 0.3 m/s) fails
    drifts = [dict(r, lin_vel_error_mps=0.2) if r["command"] == "stop" else r for r in table(0.2)]
    assert command_score(drifts) > 1.0
