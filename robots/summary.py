"""A human-readable summary of the G1 model (``a2cf-mb info``)."""

from __future__ import annotations

import mujoco

from robots import g1
from robots.assets import g1_urdf_path
from robots.mujoco_model import build_mujoco_model
from robots.pinocchio_model import build_pinocchio_model


def describe_g1() -> str:
    """Multi-line text: model files, DoF, mass, and the joint table with limits and gains."""
    robot = build_pinocchio_model()
    mj = build_mujoco_model()
    lines = [
        "Unitree G1 (29 DoF, rev 1.0)",
        f"  URDF            {g1_urdf_path()}",
        f"  Pinocchio       nq={robot.model.nq} nv={robot.model.nv} (free-flyer, quaternion xyzw)",
        f"  MuJoCo          nq={mj.nq} nv={mj.nv} nu={mj.nu} dt={mj.opt.timestep} s "
        f"(mujoco {mujoco.__version__})",
        f"  total mass      {robot.total_mass_kg:.3f} kg",
        f"  standing pelvis {robot.q_stand[2]:.3f} m",
        f"  frames          {', '.join(f.name for f in g1.FRAMES)}",
        "",
        f"  {'#':>2} {'joint':<27} {'lower':>7} {'upper':>7} {'vel':>5} {'Kp':>6} {'Kd':>5} "
        f"{'effort':>6} {'armat.':>7} {'stand':>6}",
        f"  {'':>2} {'':<27} {'[rad]':>7} {'[rad]':>7} {'rad/s':>5} {'Nm/rd':>6} {'':>5} "
        f"{'[Nm]':>6} {'kg m2':>7} {'[rad]':>6}",
    ]
    for i, joint in enumerate(g1.JOINTS):
        lines.append(
            f"  {i:>2} {joint.name:<27} {robot.position_lower_rad[i]:>7.3f} "
            f"{robot.position_upper_rad[i]:>7.3f} {robot.velocity_limit_rad_s[i]:>5.0f} "
            f"{joint.motor.kp:>6.2f} {joint.motor.kd:>5.2f} {joint.motor.effort_nm:>6.0f} "
            f"{joint.motor.armature:>7.4f} {joint.stand_rad:>6.3f}"
        )
    return "\n".join(lines)
