""":class:`WarpPhysics`: the :class:`rl.envs.physics.Physics` interface on MuJoCo Warp (the ``gpu``
extra), on Warp's CPU device or on a CUDA GPU.

One ``mjw.Data`` holds every env as a world; a policy step is ``decimation`` calls of ``mjw.step``
(captured once in a CUDA graph on a GPU). Warp computes in float32, so ``qpos``/``qvel`` are
float32 here (float64 on MuJoCo C). The env's own tensors live on the CPU: on Warp's CPU device
the tensors handed to the env are ``wp.to_torch`` views of the worlds' arrays (no copies); on a
GPU they are CPU mirrors copied at the step boundary (about 1 KB per env and step; moving the
env's parts onto the device is what removes them, see ``docs/gpu.md``).

Domain randomisation: the :class:`rl.envs.randomization.Randomizer` still writes its ``MjModel``
copies; the fields it writes (:data:`rl.envs.randomization.MODEL_FIELDS`) are made per world
(batch size = number of copies, read by the kernels as ``field[world % copies]``, the
randomiser's own ``i % G`` rule) and copied in when an env resets, then ``mjw.set_const``
recomputes the derived fields (:data:`DERIVED_FIELDS`, batched too, else every world's
``set_const`` lands in row 0). MuJoCo C does not call ``mj_setConst`` after a randomisation, so
randomised envs differ slightly between the backends (contact regularisation via
``body_invweight0``); without randomisation they agree to float32 precision.
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np
import torch

from rl.envs.model import model_layout
from rl.envs.physics import robot_fields
from rl.envs.randomization import MODEL_FIELDS
from robots import g1

NCONMAX_PER_WORLD = 48
"""Contacts allocated per world [-] (one pool of ``48 * N`` shared by all worlds; mujoco_warp's
own G1 benchmark size; a standing G1 has 8 sole contacts, a fallen one about 20-30)."""
NJMAX_PER_WORLD = 300
"""Constraint rows per world, a hard limit [-] (mjlab's flat G1; pyramidal contacts take 4 rows
each, plus joint limits). Oversizing costs: buffers scale with it."""
DERIVED_FIELDS = ("body_subtreemass", "body_invweight0", "dof_invweight0", "actuator_acc0")
"""Model fields ``mjw.set_const`` derives from mass and CoM: per world whenever masses are."""
GPU_EXTRA_HINT = "install the gpu extra: pip install 'a2cf-mb[gpu]' (or -e '.[gpu]' in a checkout)"


class MissingExtraError(ModuleNotFoundError):
    """An optional dependency (an extra of a2cf-mb) is not installed; the message names it."""


def import_warp() -> tuple[Any, Any]:
    """``(warp, mujoco_warp)``, or an error naming the extra to install."""
    try:
        import mujoco_warp as mjw
        import warp as wp
    except ImportError as err:
        raise MissingExtraError(
            f"EnvConfig.backend='warp' needs mujoco-warp, which cannot be imported ({err}); "
            f"{GPU_EXTRA_HINT}, or use --env-backend mujoco."
        ) from err
    wp.config.quiet = True  # no banner, and no line per kernel module loaded (hundreds):
    wp.config.log_level = wp.LOG_WARNING
    return wp, mjw


def _fatal_overflow(mjw: Any) -> int:
    """Overflow bits that leave a world's step wrong (buffers too small). Solver iteration limits
    (ITERATIONS, LS_ITERATIONS) are not among them: MuJoCo C carries on after those too."""
    o = mjw.OverflowType
    return int(o.NEFC | o.NJMAX_NNZ | o.BROADPHASE | o.NARROWPHASE | o.CCD)


class WarpPhysics:
    """:class:`rl.envs.physics.Physics` on MuJoCo Warp: N worlds of one ``mjw.Data``.

    ``device`` is Warp's device (``"cpu"``, ``"cuda"``, ``"cuda:0"``); the tensors the env sees are
    on the CPU either way (views on Warp's CPU device, mirrors on a GPU).
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        models: list[mujoco.MjModel],
        decimation: int,
        max_abs_qvel: float,
        device: str = "cpu",
    ) -> None:
        """``model``: the nominal model; ``models`` (N,): the model of each env (the randomiser's
        copies, env i using copy i % G); ``max_abs_qvel`` [m/s, rad/s]: the divergence guard."""
        wp, mjw = self._wp, self._mjw = import_warp()
        if device.startswith("cuda") and not wp.is_cuda_available():
            raise ValueError(
                f"EnvConfig.device '{device}': Warp finds no CUDA device on this machine; run "
                "with --env-device cpu (Warp's CPU device, slow) or --env-backend mujoco."
            )
        n = self.num_envs = len(models)
        self.decimation = decimation
        self.max_abs_qvel = max_abs_qvel
        self.model, self.models = model, models
        self.layout = lay = model_layout(model)
        self.physics_dt_s = float(model.opt.timestep)
        self.device = wp.get_device(device)
        self.copies = _model_copies(models)
        k = len(self.copies)
        batch = dict.fromkeys(MODEL_FIELDS + DERIVED_FIELDS, k) if k > 1 else None
        with wp.ScopedDevice(self.device):
            self.m = mjw.put_model(model, batch_sizes=batch)
            self.d = mjw.make_data(
                model, nworld=n, nconmax=NCONMAX_PER_WORLD, njmax=NJMAX_PER_WORLD
            )
        d = self.d
        self._sim = {  # torch views of the worlds' arrays (on Warp's device)
            "qpos": wp.to_torch(d.qpos),
            "qvel": wp.to_torch(d.qvel),
            "ctrl": wp.to_torch(d.ctrl),
            "xfrc_applied": wp.to_torch(d.xfrc_applied),  # (N, nbody, 6): force_w, torque_w
            "sensordata": wp.to_torch(d.sensordata),
        }
        self._time = wp.to_torch(d.time)
        self._warmstart = wp.to_torch(d.qacc_warmstart)
        self._overflow = wp.to_torch(d.overflow)
        self._fatal = _fatal_overflow(mjw)
        on_cpu = self.device.is_cpu
        # what the env reads and writes: the views themselves, or CPU mirrors on a GPU
        self._host = {k: (v if on_cpu else v.cpu()) for k, v in self._sim.items()}
        self.qpos, self.qvel = self._host["qpos"], self._host["qvel"]
        self.stand_qpos = torch.as_tensor(lay.stand_state[lay.qpos], dtype=torch.float64)
        self.stand_qvel = torch.as_tensor(lay.stand_state[lay.qvel], dtype=torch.float64)
        self._stand_ctrl = torch.as_tensor(g1.STAND_JOINT_POS_RAD, dtype=torch.float32)
        self._model_views = {
            f: wp.to_torch(getattr(self.m, f)) for f in MODEL_FIELDS if k > 1
        }  # (G, ...) per-world model fields
        self._models_dirty = k > 1  # copy every model row in before the next step
        self._graph = None  # CUDA graph of decimation steps, captured on the second step
        self._graph_ready = False
        self.diverged_total = 0

    # ---------------------------------------------------------------- host <-> device
    def _push(self, *names: str) -> None:
        """Copy CPU mirrors to the device (nothing to do on Warp's CPU device)."""
        if not self.device.is_cpu:
            for name in names:
                self._sim[name].copy_(self._host[name])

    def _pull(self, *names: str) -> None:
        """Copy device arrays to the CPU mirrors (nothing to do on Warp's CPU device)."""
        if not self.device.is_cpu:
            for name in names:
                self._host[name].copy_(self._sim[name])

    # ---------------------------------------------------------------- Physics
    def set_controls(self, joint_targets_rad: torch.Tensor, wrench_w: torch.Tensor) -> None:
        """Hold the joint targets (N, 29) [rad] and the pelvis ``xfrc_applied`` (N, 6) (world-frame
        force [N] and torque [Nm] at the pelvis CoM, as MuJoCo C takes it) over the next step."""
        self._host["ctrl"][:] = joint_targets_rad
        self._host["xfrc_applied"][:, self.layout.pelvis_body] = wrench_w

    def step(self) -> torch.Tensor:
        """``decimation`` physics steps of every world; returns (N,) bool, the worlds that were
        non-finite before, went non-finite, exceeded ``max_abs_qvel`` or overflowed a buffer:
        they are counted and hold the standing keyframe until the env resets them."""
        qpos, qvel = self._host["qpos"], self._host["qvel"]
        bad_in = ~(torch.isfinite(qpos).all(dim=1) & torch.isfinite(qvel).all(dim=1))
        if bad_in.any():
            self._stand_rows(bad_in.nonzero().flatten())
        self._push("qpos", "qvel", "ctrl", "xfrc_applied")
        if self._models_dirty:
            self._sync_models(range(len(self.copies)))
        self._advance()
        self._pull("qpos", "qvel", "sensordata")
        sens = self._host["sensordata"]
        finite = torch.isfinite(qpos).all(dim=1) & torch.isfinite(qvel).all(dim=1)
        finite &= torch.isfinite(sens).all(dim=1)
        calm = torch.nan_to_num(qvel, nan=torch.inf).abs().amax(dim=1) < self.max_abs_qvel
        overflow = (self._overflow & self._fatal).cpu() != 0
        diverged = bad_in | ~finite | ~calm | overflow
        num_diverged = int(diverged.sum())
        if num_diverged:
            rows = diverged.nonzero().flatten()
            self._stand_rows(rows)
            sens[rows] = 0.0
            self._push("qpos", "qvel", "sensordata")
            self.diverged_total += num_diverged
        return diverged

    def _advance(self) -> None:
        """``decimation`` ``mjw.step`` calls (replayed from a CUDA graph after the first step)."""
        wp, mjw = self._wp, self._mjw
        if self.device.is_cuda and self._graph_ready:
            if self._graph is None:  # kernels are compiled by now: capture once
                with wp.ScopedDevice(self.device), wp.ScopedCapture() as capture:
                    for _ in range(self.decimation):
                        mjw.step(self.m, self.d)
                self._graph = capture.graph
            wp.capture_launch(self._graph)
            return
        with wp.ScopedDevice(self.device):
            for _ in range(self.decimation):
                mjw.step(self.m, self.d)
        self._graph_ready = True

    def _stand_rows(self, rows: torch.Tensor) -> None:
        """Put worlds ``rows`` (M,) at the standing keyframe, time 0, no warm start, no overflow
        (the placeholder until the env resets them; the caller pushes qpos/qvel)."""
        self._host["qpos"][rows] = self.stand_qpos.float()
        self._host["qvel"][rows] = self.stand_qvel.float()
        sim_rows = rows.to(self._time.device)
        self._time[sim_rows] = 0.0
        self._warmstart[sim_rows] = 0.0
        self._overflow[sim_rows] = 0

    def reset_rows(self, env_ids: torch.Tensor, qpos: torch.Tensor, qvel: torch.Tensor) -> None:
        """Start worlds ``env_ids`` (M,) from ``qpos`` (M, 36), ``qvel`` (M, 35) at time 0 with
        their (re)randomised model rows; sensors recomputed at the stand targets, no wrench."""
        self._stand_rows(env_ids)
        self._host["qpos"][env_ids] = qpos.float()
        self._host["qvel"][env_ids] = qvel.float()
        self._host["ctrl"][env_ids] = self._stand_ctrl
        self._host["xfrc_applied"][env_ids] = 0.0
        self._push("qpos", "qvel", "ctrl", "xfrc_applied")
        if len(self.copies) > 1:
            self._sync_models(sorted({i % len(self.copies) for i in env_ids.tolist()}))
        self.refresh_sensors(env_ids)

    def refresh_sensors(self, env_ids: torch.Tensor) -> None:
        """Recompute the sensor rows of ``env_ids`` (M,) from the current state and controls.
        ``mjw.forward`` runs every world; the other worlds keep their sensor rows."""
        sens = self._sim["sensordata"]
        keep = sens.clone()
        with self._wp.ScopedDevice(self.device):
            self._mjw.forward(self.m, self.d)
        others = torch.ones(self.num_envs, dtype=torch.bool)
        others[env_ids] = False
        sens[others.to(sens.device)] = keep[others.to(sens.device)]
        self._pull("sensordata")

    def _sync_models(self, rows) -> None:
        """Copy the randomised fields of model copies ``rows`` into their world rows and recompute
        the derived fields (``mjw.set_const``: masses, CoM, inverse weights of every row)."""
        rows = list(rows)
        for field, view in self._model_views.items():
            values = np.stack([getattr(self.copies[r], field) for r in rows])
            view[rows] = torch.as_tensor(values, dtype=view.dtype).to(view.device)
        with self._wp.ScopedDevice(self.device):
            self._mjw.set_const(self.m, self.d)
        self._models_dirty = False

    def read(self) -> dict[str, Any]:
        """The robot fields of :class:`rl.envs.state.EnvState` (float32 CPU tensors, copies)."""
        h = self._host
        return robot_fields(self.layout, h["qpos"], h["qvel"], h["sensordata"])

    @property
    def state(self) -> np.ndarray:
        """(N, nstate) FULLPHYSICS-layout rows (time, qpos, qvel filled; the rest the keyframe's):
        a read-only float64 snapshot, for readers written against MuJoCo C's ``env.state``."""
        lay = self.layout
        rows = np.tile(lay.stand_state, (self.num_envs, 1))
        rows[:, lay.time] = self._time.cpu().double().numpy()
        rows[:, lay.qpos] = self.qpos.double().numpy()
        rows[:, lay.qvel] = self.qvel.double().numpy()
        rows.flags.writeable = False
        return rows

    def state_dict(self) -> dict[str, Any]:
        """The worlds' state (qpos, qvel, time, warm start), sensor rows and divergence count."""
        return {
            "warp_qpos": self.qpos.clone(),
            "warp_qvel": self.qvel.clone(),
            "warp_time": self._time.cpu().clone(),
            "warp_qacc_warmstart": self._warmstart.cpu().clone(),
            "sensordata": self._host["sensordata"].clone(),
            "diverged_total": self.diverged_total,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` output of a Warp physics of the same size; the model rows
        are copied in again before the next step (the randomiser loads after the physics)."""
        if "warp_qpos" not in state:
            raise ValueError(
                "env checkpoint written by the MuJoCo C backend; resume it with --env-backend "
                "mujoco (states do not carry over between backends)"
            )
        if state["warp_qpos"].shape != self.qpos.shape:
            raise ValueError(
                f"env checkpoint holds {state['warp_qpos'].shape[0]} envs, this env has "
                f"{self.num_envs}: resume with the run's own config"
            )
        self.qpos[:] = state["warp_qpos"]
        self.qvel[:] = state["warp_qvel"]
        self._host["sensordata"][:] = state["sensordata"]
        self._time[:] = state["warp_time"].to(self._time.device)
        self._warmstart[:] = state["warp_qacc_warmstart"].to(self._warmstart.device)
        self._push("qpos", "qvel", "sensordata")
        self.diverged_total = int(state["diverged_total"])
        self._models_dirty = len(self.copies) > 1

    def close(self) -> None:
        """Drop the graph and the device arrays."""
        self._graph = None
        self._sim.clear()


def _model_copies(models: list[mujoco.MjModel]) -> list[mujoco.MjModel]:
    """The distinct models of ``models`` (N,), checked to follow the randomiser's rule (env i
    steps with copy i % G), which is how Warp reads a per-world field of G rows."""
    copies: list[mujoco.MjModel] = []
    for model in models:
        if all(model is not c for c in copies):
            copies.append(model)
    k = len(copies)
    if any(model is not copies[i % k] for i, model in enumerate(models)):
        raise ValueError(
            "WarpPhysics: env i must step with model copy i % G (the Randomizer's rule); "
            "got another assignment of models to envs"
        )
    return copies
