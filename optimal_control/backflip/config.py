"""Configuration of the backflip trajectory optimisation: phases, limits, weights, solver."""

from __future__ import annotations

import math
from dataclasses import dataclass

from optimal_control.validation import require_finite_fields, require_within

PHASE_NAMES: tuple[str, ...] = ("stand", "crouch", "jump", "air", "land")
"""The paper's backflip FSM phases, in order (index = phase id 0..4)."""
STANCE_PHASES = (0, 1, 2, 4)
"""Phases with both soles on the ground."""
AIR_PHASE = 3
MAX_PHASE_INTERVALS = 100
"""Most time intervals (knots - 1) in one phase: each knot adds the robot's state, torques and
contact forces to the NLP (the defaults use 3 to 24 per phase), and building and solving it grows
with them."""


@dataclass(frozen=True)
class PhaseSpec:
    """One phase of the flip: knots and duration bounds (the duration is a decision variable)."""

    intervals: int  # number of time intervals (knots - 1) in the phase
    min_duration_s: float  # lower bound on the phase duration [s]
    max_duration_s: float  # upper bound on the phase duration [s]
    guess_duration_s: float  # initial guess of the duration [s]


@dataclass(frozen=True)
class BackflipConfig:
    """Everything the backflip TO needs; flat scalars are exposed as CLI flags."""

    stand_intervals: int = 3  # intervals in Stand
    crouch_intervals: int = 10  # intervals in Crouch
    jump_intervals: int = 10  # intervals in Jump (push-off)
    air_intervals: int = 24  # intervals in Air
    land_intervals: int = 16  # intervals in Land
    stand_duration_s: tuple[float, float, float] = (0.06, 0.3, 0.1)  # Stand (min, max, guess) [s]
    crouch_duration_s: tuple[float, float, float] = (0.3, 0.7, 0.5)  # Crouch (min, max, guess) [s]
    jump_duration_s: tuple[float, float, float] = (0.15, 0.5, 0.25)  # Jump (min, max, guess) [s]
    air_duration_s: tuple[float, float, float] = (0.35, 0.8, 0.55)  # Air (min, max, guess) [s]
    land_duration_s: tuple[float, float, float] = (0.3, 0.8, 0.6)  # Land (min, max, guess) [s]
    turn_rad: float = -2 * math.pi  # pitch turn: -2 pi a backflip, 0 a jump [rad]
    torque_scale: float = 1.0  # alpha: torque limits are alpha * effort limit [-]
    held_joint_torque_fraction: float = 0.8  # share of alpha for joints the TO does not move [-]
    max_stance_lean_rad: float = 0.35  # |base pitch| bound on the ground (from 0, or -2 pi) [rad]
    friction_coefficient: float = 0.7  # sole friction pyramid coefficient mu [-]
    max_wrench_force_n: float = 400.0  # bound on each pelvis wrench force component [N]
    max_wrench_torque_nm: float = 200.0  # bound on each pelvis wrench torque component [Nm]
    forbid_wrench: bool = False  # the pelvis wrench fixed to zero (no help allowed)
    # robots.g1's actuator force ranges: 50 N m at the ankles and the waist roll/pitch (the
    # two-motor linkages), where the URDF's effort limits say 35 N m
    actuator_effort_limits: bool = False  # plan within the simulator's actuator force ranges
    # continuation: per stage, the weight of the integral of |w / (100 N, 30 Nm)|^2
    wrench_weights: tuple[float, ...] = (1e-3, 1e-1, 10.0, 1e3)  # help cost per stage [1/s]
    midpoint_constraints: bool = True  # dynamics and torque limits also at interval midpoints
    # joint position and speed limits on the whole interpolant between knots (its Bernstein
    # control points are bounded), not only at the knots
    limits_between_knots: bool = True  # joint limits hold between knots too
    # with the midpoint constraints: the torque peaks between knot and midpoint are bounded
    quarter_point_torques: bool = False  # torque limits also at interval quarter points
    # after the solve, warm re-solves (same solver, no rebuild) tighten the knot and midpoint torque
    # bounds of the intervals whose 1 kHz interpolant exceeds the limit
    torque_refinements: int = 5  # most re-solves that tighten exceeded torque bounds [-]
    # knot and midpoint torques stay within (1 - margin) x alpha x effort limit: headroom for the
    # torque between those samples (see torque_refinements)
    torque_limit_margin: float = 0.005  # torque headroom below alpha x effort limit [-]
    torque_weight: float = 1e-3  # cost on (tau / tau_max)^2 integrated over time [1/s]
    acceleration_weight: float = 1e-4  # cost on joint accelerations^2 integrated [s^3/rad^2]
    min_pelvis_height_m: float = 0.4  # pelvis origin stays this high throughout [m]
    min_limb_height_m: float = 0.1  # hands and knees stay this high throughout [m]
    # the shins' collision boxes (the training env's primitives, which enclose the URDF meshes)
    # stay min_shin_height_m high at every knot; off: a deep crouch may rest them on the floor
    shin_clearance: bool = False  # shin collision boxes stay min_shin_height_m high
    min_shin_height_m: float = 0.02  # [m]
    cop_margin: float = 0.15  # least share of the sole load on heel and on toe [-]
    sole_drift_tolerance_m: float = 0.002  # stance soles stay this close to their placement [m]
    min_air_sole_height_m: float = 0.0  # sole corners above the floor in the air [m]
    final_joint_tolerance_rad: float = 0.1  # landed joints within this of the stand pose [rad]
    max_iter: int = 400  # IPOPT iterations per continuation stage [-]
    tol: float = 1e-6  # IPOPT convergence tolerance [-]
    symbolic: str = "SX"  # NLP graph: "SX" (inlined) or "MX" (mapped SX functions)
    hessian: str = "exact"  # IPOPT Hessian: "exact" or "limited-memory"
    print_level: int = 0  # IPOPT print level (0 silent, 5 verbose) [-]
    warm_start: str = ""  # path of a cached solution (npz) to warm-start from; "" = cold
    cache_dir: str = "~/.cache/a2cf-mb/backflip"  # solution cache; "" = none

    def __post_init__(self) -> None:
        """Reject NaN / inf values and knot counts out of bounds, naming the field and its flag."""
        require_finite_fields(self)
        for name in PHASE_NAMES:
            require_within(
                self, f"{name}_intervals", 1, MAX_PHASE_INTERVALS, "intervals",
                why="each knot adds the robot's state, torques and contact forces to the NLP, and "
                "building and solving it grows with them (the defaults use 3 to 24 per phase)",
            )  # fmt: skip

    def phases(self) -> tuple[PhaseSpec, ...]:
        """The five phases as :class:`PhaseSpec`, in :data:`PHASE_NAMES` order."""
        counts = (
            self.stand_intervals,
            self.crouch_intervals,
            self.jump_intervals,
            self.air_intervals,
            self.land_intervals,
        )
        bounds = (
            self.stand_duration_s,
            self.crouch_duration_s,
            self.jump_duration_s,
            self.air_duration_s,
            self.land_duration_s,
        )
        out = []
        for name, n, (lo, hi, guess) in zip(PHASE_NAMES, counts, bounds, strict=True):
            if not 0.0 < lo <= hi:
                raise ValueError(
                    f"Phase '{name}' duration bounds ({lo}, {hi}) must be 0 < min <= max."
                )
            out.append(PhaseSpec(n, lo, hi, min(max(guess, lo), hi)))
        return tuple(out)

    def validate(self) -> BackflipConfig:
        """Check values a user can get wrong; return self."""
        self.phases()
        if self.torque_scale < 0.0:
            raise ValueError(f"torque_scale (alpha) must be >= 0, got {self.torque_scale}.")
        if self.friction_coefficient <= 0.0:
            raise ValueError(f"friction_coefficient must be > 0, got {self.friction_coefficient}.")
        if self.hessian not in ("exact", "limited-memory"):
            raise ValueError(f"hessian must be 'exact' or 'limited-memory', got '{self.hessian}'.")
        if self.symbolic not in ("MX", "SX"):
            raise ValueError(f"symbolic must be 'MX' or 'SX', got '{self.symbolic}'.")
        if not 0.0 <= self.torque_limit_margin < 1.0:
            raise ValueError(
                f"torque_limit_margin must be in [0, 1), got {self.torque_limit_margin}."
            )
        if not self.wrench_weights:
            raise ValueError("wrench_weights needs at least one continuation stage.")
        return self


def tiny_hop_config() -> BackflipConfig:
    """A small vertical hop (no turn) on a coarse grid: the same NLP as the flip, solved in
    seconds; used by the quick benchmark and the tests."""
    return BackflipConfig(
        stand_intervals=1,
        crouch_intervals=4,
        jump_intervals=4,
        air_intervals=5,
        land_intervals=5,
        turn_rad=0.0,
        wrench_weights=(10.0,),
        stand_duration_s=(0.05, 0.1, 0.05),
        crouch_duration_s=(0.2, 0.3, 0.25),
        jump_duration_s=(0.1, 0.2, 0.15),
        air_duration_s=(0.15, 0.3, 0.2),
        land_duration_s=(0.25, 0.35, 0.3),
    )
