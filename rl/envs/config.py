"""Configuration of the batched G1 environment (:class:`rl.envs.G1VecEnv`)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class EnvConfig:
    """Sizes, timing, noise, domain randomisation and assist defaults of a :class:`G1VecEnv`.

    Flat on purpose: every field is a command-line flag through :mod:`a2cf_mb.config_cli`.
    The physics step itself (0.005 s) belongs to :class:`robots.mujoco_model.MujocoModelConfig`.
    """

    num_envs: int = 64  # parallel G1 instances [-]
    decimation: int = 4  # physics steps per policy step (0.005 s x 4 = 50 Hz policy) [-]
    episode_length_s: float = 10.0  # episode duration before a time-out [s]
    num_threads: int = 0  # physics threads of the rollout pool; 0 = all cores [-]
    seed: int = 0  # seed of the env's random generators [-]
    history_length: int = 5  # policy observations kept in the "history" group (H) [-]
    clip_actions: float = 100.0  # actions are clipped to +- this before use [-]

    # Observation noise (uniform, +- value) on the "policy" group; 0 disables one term.
    noise: bool = True  # add observation noise to the "policy" group
    noise_ang_vel_rps: float = 0.2  # base angular velocity noise [rad/s]
    noise_gravity: float = 0.05  # projected gravity noise [-]
    noise_joint_pos_rad: float = 0.01  # joint position noise [rad]
    noise_joint_vel_rps: float = 1.5  # joint velocity noise [rad/s]

    # Initial state at reset.
    reset_joint_pos_noise_rad: float = (
        0.05  # uniform +- offset of each joint from the stand pose [rad]
    )
    reset_base_vel_noise_mps: float = 0.1  # uniform +- base linear / angular velocity [m/s, rad/s]
    reset_random_yaw: bool = True  # random base heading at reset

    # Domain randomisation, resampled per env at each of its resets.
    randomize: bool = True  # master switch of friction / payload / CoM randomisation
    friction_range: tuple[float, float] = (0.4, 1.25)  # sole and floor sliding friction [-]
    payload_mass_range_kg: tuple[float, float] = (-1.0, 3.0)  # mass added to the payload body [kg]
    com_offset_range_m: tuple[float, float] = (
        -0.03,
        0.03,
    )  # CoM shift of the payload body, per axis [m]
    payload_body: str = "torso_link"  # body receiving payload and CoM offset (MuJoCo body name)
    pushes: bool = True  # random pushes (base velocity kicks)
    push_interval_range_s: tuple[float, float] = (3.0, 6.0)  # time between two pushes [s]
    push_velocity_xy_mps: float = 0.5  # max +- horizontal base velocity change of a push [m/s]

    # Divergence guard: rows beyond these are counted as diverged, reset and reported done.
    max_abs_qvel: float = 200.0  # largest plausible |qvel| entry [m/s, rad/s]

    # Assist (A2CF) defaults; the runner changes them through the env's setters.
    assist_enabled: bool = True  # apply the assist head's pelvis wrench
    random_mask_prob: float = 0.2  # zeta: probability of dropping each wrench component [-]
    less_assist_reward: bool = False  # add the less-assist reward exp(-2|F|/|eta|)

    def __post_init__(self) -> None:
        if self.num_envs < 1:
            raise ValueError(f"EnvConfig.num_envs must be >= 1, got {self.num_envs}.")
        if self.decimation < 1:
            raise ValueError(f"EnvConfig.decimation must be >= 1, got {self.decimation}.")
        if self.episode_length_s <= 0:
            raise ValueError(
                f"EnvConfig.episode_length_s must be positive, got {self.episode_length_s}."
            )
        if self.history_length < 1:
            raise ValueError(f"EnvConfig.history_length must be >= 1, got {self.history_length}.")
        if not 0.0 <= self.random_mask_prob <= 1.0:
            raise ValueError(
                f"EnvConfig.random_mask_prob (zeta) must be in [0, 1], got {self.random_mask_prob}."
            )
        for name in (
            "friction_range",
            "payload_mass_range_kg",
            "com_offset_range_m",
            "push_interval_range_s",
        ):
            low, high = getattr(self, name)
            if low > high:
                raise ValueError(
                    f"EnvConfig.{name} must be (low, high) with low <= high, got {(low, high)}."
                )
        if self.friction_range[0] <= 0:
            raise ValueError(
                f"EnvConfig.friction_range must be positive, got {self.friction_range}."
            )
        if self.push_interval_range_s[0] <= 0:
            raise ValueError(
                f"EnvConfig.push_interval_range_s must be positive, got {self.push_interval_range_s}."
            )
