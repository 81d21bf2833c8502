""":class:`WarpPhysics`: the :class:`rl.envs.physics.Physics` interface on MuJoCo Warp (the ``gpu``
extra), on Warp's CPU device or on a CUDA GPU.

One ``mjw.Data`` holds every env as a world; a policy step is ``decimation`` calls of ``mjw.step``
and a reset one call of ``mjw.forward`` (sensors of the new rows), each captured once in a Warp
graph and replayed (on a GPU whose Warp memory pool is on; on request on Warp's CPU device too).
Warp computes in float32,
so ``qpos``/``qvel`` are float32 here (float64 on MuJoCo C). The tensors handed to the env
(``qpos``, ``qvel``, the readings of :meth:`WarpPhysics.read`) are ``wp.to_torch`` views of the
worlds' arrays, and the joint targets and the pelvis wrench are written into such views: on
Warp's CPU device and on a GPU alike, a step copies nothing between host and device (the env's
parts live on the same device, see ``docs/gpu.md``), and waits on the device nowhere: bad rows are
replaced with ``torch.where`` masks, the divergence count stays on the device, and the contact
pool's overflow flag goes to the host with the env's one batch of host values per step
(:meth:`WarpPhysics.fault_flags`). What goes through host memory, at resets of randomised envs
only: the randomised ``MjModel`` rows (copied into the per-world model arrays) and the env ids of
the model rows to copy.

Domain randomisation: the :class:`rl.envs.randomization.Randomizer` still writes its ``MjModel``
copies; the fields it writes (:data:`rl.envs.randomization.MODEL_FIELDS`) are made per world
(batch size = number of copies, read by the kernels as ``field[world % copies]``, the
randomiser's own ``i % G`` rule) and copied in when an env resets. ``mjw.set_const`` is not
called: MuJoCo C never calls ``mj_setConst`` after writing a payload either, so the derived
fields (subtree masses, inverse weights) stay the nominal model's on both backends, and a reset
costs no 769 eager kernel launches over every world.
"""

from __future__ import annotations

import gc
from collections.abc import Callable
from typing import Any

import mujoco
import numpy as np
import torch

from rl.envs.config import NCONMAX_PER_WORLD, NJMAX_PER_WORLD
from rl.envs.model import model_layout
from rl.envs.physics import robot_fields
from rl.envs.randomization import MODEL_FIELDS
from robots import g1

GPU_EXTRA_HINT = "install the gpu extra: pip install 'a2cf-mb[gpu]' (or -e '.[gpu]' in a checkout)"


class MissingExtraError(ModuleNotFoundError):
    """An optional dependency (an extra of a2cf-mb) is not installed; the message names it."""


class ContactPoolOverflowError(RuntimeError):
    """MuJoCo Warp's contact pool, shared by all worlds, was too small for a step: every world's
    step is wrong. The message names the sizes and how to raise them."""


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
    """Overflow bits that leave one world's step wrong (its own buffers too small): that world is
    reset. Solver iteration limits (ITERATIONS, LS_ITERATIONS) are not among them: MuJoCo C
    carries on after those too. The shared contact pool's bits are :func:`_pool_overflow`'s."""
    o = mjw.OverflowType
    return int(o.NEFC | o.NJMAX_NNZ | o.CCD)


def _pool_overflow(mjw: Any) -> int:
    """Overflow bits of the contact pool all worlds share: mujoco_warp sets them on every world."""
    o = mjw.OverflowType
    return int(o.BROADPHASE | o.NARROWPHASE)


def _contact_pool_message(ncollision: int, nacon: int, naconmax: int, nworld: int) -> str:
    """What :class:`ContactPoolOverflowError` says: the pool's size and what a step asked of it
    (``ncollision`` broadphase pairs, ``nacon`` contacts; mujoco_warp counts past the pool)."""
    per_world = naconmax // nworld
    asked = max(ncollision, nacon)
    need = -(-asked // nworld)  # ceil: the pool is per_world * nworld
    return (
        f"MuJoCo Warp's contact pool overflowed: a step asked for {ncollision} broadphase pairs "
        f"and {nacon} contacts, the pool holds naconmax = {naconmax} ({per_world} per world x "
        f"{nworld} worlds), so every world's step is wrong. Raise the contacts per world to at "
        f"least {need} (what this step asked for; leave room for more) with "
        f"--env-warp-nconmax-per-world N (EnvConfig.warp_nconmax_per_world, now {per_world}). "
        "Fewer envs do not help: the pool is sized per world."
    )


def cuda_graphs_usable(wp: Any, device: Any) -> bool:
    """Whether the step is replayed from a CUDA graph on Warp ``device``: a CUDA device with
    Warp's memory pool on (``mjw.step`` allocates arrays inside the capture, which needs the
    pool's stream-ordered allocations; mjlab checks the same). Elsewhere the step runs eagerly."""
    return bool(device.is_cuda and wp.is_mempool_enabled(device))


def capture_graph(wp: Any, device: Any, launches: Callable[[], None]) -> Any:
    """A Warp graph of the kernels ``launches`` issues on ``device``. Python's garbage collector
    is paused meanwhile: a collection could release Warp arrays or modules, which must not be
    freed inside a capture."""
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        with wp.ScopedDevice(device), wp.ScopedCapture(device=device) as capture:
            launches()
    finally:
        if was_enabled:
            gc.enable()
    return capture.graph


class WarpPhysics:
    """:class:`rl.envs.physics.Physics` on MuJoCo Warp: N worlds of one ``mjw.Data``.

    ``device`` is Warp's device (``"cpu"``, ``"cuda"``, ``"cuda:0"``); the tensors the env sees are
    views of the worlds' arrays on that device (``torch_device``), never copies.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        models: list[mujoco.MjModel],
        decimation: int,
        max_abs_qvel: float,
        device: str = "cpu",
        *,
        nconmax_per_world: int = NCONMAX_PER_WORLD,
        njmax_per_world: int = NJMAX_PER_WORLD,
        graphs: bool | None = None,
    ) -> None:
        """``model``: the nominal model; ``models`` (N,): the model of each env (the randomiser's
        copies, env i using copy i % G); ``max_abs_qvel`` [m/s, rad/s]: the divergence guard;
        ``nconmax_per_world`` [-]: the shared contact pool's size per world; ``njmax_per_world``
        [-]: constraint rows per world; ``graphs``: replay the step and the reset's ``forward``
        from Warp graphs (None: where :func:`cuda_graphs_usable`; True also works on Warp's CPU
        device, which the tests use)."""
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
        batch = dict.fromkeys(MODEL_FIELDS, k) if k > 1 else None
        with wp.ScopedDevice(self.device):
            self.m = mjw.put_model(model, batch_sizes=batch)
            self.d = mjw.make_data(
                model, nworld=n, nconmax=nconmax_per_world, njmax=njmax_per_world
            )
        d = self.d
        # The env's tensors live on the torch device of Warp's. Ordering between torch's work and
        # Warp's launches on a GPU: Warp's streams are blocking streams, which the legacy default
        # stream torch uses synchronises with, so no explicit events are needed.
        self.torch_device = dev = wp.device_to_torch(self.device)
        self._sim = {  # torch views of the worlds' arrays (on Warp's device): what the env reads
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
        self._pool = _pool_overflow(mjw)
        self.qpos, self.qvel = self._sim["qpos"], self._sim["qvel"]
        stand = torch.as_tensor(lay.stand_state, dtype=torch.float64)
        self.stand_qpos = stand[lay.qpos].to(dev)
        self.stand_qvel = stand[lay.qvel].to(dev)
        self._stand_qpos32, self._stand_qvel32 = self.stand_qpos.float(), self.stand_qvel.float()
        self._stand_ctrl = torch.as_tensor(g1.STAND_JOINT_POS_RAD, dtype=torch.float32, device=dev)
        self._model_views = {
            f: wp.to_torch(getattr(self.m, f)) for f in MODEL_FIELDS if k > 1
        }  # (G, ...) per-world model fields
        self._models_dirty = k > 1  # copy every model row in before the next step
        self._use_graph = cuda_graphs_usable(wp, self.device) if graphs is None else graphs
        self._graphs: dict[str, Any] = {}  # "step", "forward": captured after their first run
        self._ran: set[str] = set()  # launched eagerly once: kernels compiled, ready to capture
        # Counted on the device: the env fetches it with its batch of host values (never a sync).
        self.diverged_counter = torch.zeros((), dtype=torch.long, device=dev)
        # The contact pool's overflow, sticky, with the sizes a step asked for (ncollision, nacon).
        self._pool_fault = torch.zeros(3, dtype=torch.long, device=dev)
        self._pool_sizes = wp.to_torch(d.ncollision), wp.to_torch(d.nacon)

    @property
    def diverged_total(self) -> int:
        """Rows replaced since the start because they diverged (a host read: a sync on a GPU)."""
        return int(self.diverged_counter)

    # ---------------------------------------------------------------- Physics
    def set_controls(self, joint_targets_rad: torch.Tensor, wrench_w: torch.Tensor) -> None:
        """Hold the joint targets (N, 29) [rad] and the pelvis ``xfrc_applied`` (N, 6) (world-frame
        force [N] and torque [Nm] at the pelvis CoM, as MuJoCo C takes it) over the next step.
        Both are tensors on :attr:`torch_device`, written into the worlds' arrays there."""
        self._sim["ctrl"][:] = joint_targets_rad
        self._sim["xfrc_applied"][:, self.layout.pelvis_body] = wrench_w

    def step(self) -> torch.Tensor:
        """``decimation`` physics steps of every world; returns (N,) bool, the worlds that were
        non-finite before, went non-finite, exceeded ``max_abs_qvel`` or overflowed a buffer of
        their own: they are counted and hold the standing keyframe until the env resets them.
        An overflow of the contact pool all worlds share is recorded for :meth:`raise_on_faults`
        (resetting every world would hide it). Nothing here waits for the device."""
        qpos, qvel, sens = self.qpos, self.qvel, self._sim["sensordata"]
        bad_in = ~(torch.isfinite(qpos).all(dim=1) & torch.isfinite(qvel).all(dim=1))
        self._stand_where(bad_in)
        if self._models_dirty:
            self._sync_models(range(len(self.copies)))
        self._launch("step", self._steps)
        finite = torch.isfinite(qpos).all(dim=1) & torch.isfinite(qvel).all(dim=1)
        finite &= torch.isfinite(sens).all(dim=1)
        calm = torch.nan_to_num(qvel, nan=torch.inf).abs().amax(dim=1) < self.max_abs_qvel
        overflow = (self._overflow & self._fatal) != 0
        diverged = bad_in | ~finite | ~calm | overflow
        pool = ((self._overflow & self._pool) != 0).any()
        asked = torch.stack(
            [pool.long(), self._pool_sizes[0][0].long(), self._pool_sizes[1][0].long()]
        )
        first = pool & (self._pool_fault[0] == 0)  # keep the first overflow's sizes
        self._pool_fault.copy_(torch.where(first, asked, self._pool_fault))
        self._stand_where(diverged)
        sens.masked_fill_(diverged[:, None], 0.0)
        self.diverged_counter += diverged.sum()
        return diverged

    def fault_flags(self) -> dict[str, torch.Tensor]:
        """Device scalars the env fetches with its batch of host values after a step: the contact
        pool's overflow flag and the broadphase pairs and contacts the step asked for."""
        flag, ncollision, nacon = self._pool_fault
        return {"pool_overflow": flag, "ncollision": ncollision, "nacon": nacon}

    def raise_on_faults(self, host: dict[str, float]) -> None:
        """Raise :class:`ContactPoolOverflowError` if ``host`` (:meth:`fault_flags` on the host)
        says the contact pool overflowed."""
        if host["pool_overflow"]:
            d = self.d
            message = _contact_pool_message(
                int(host["ncollision"]), int(host["nacon"]), d.naconmax, d.nworld
            )
            raise ContactPoolOverflowError(message)

    def _steps(self) -> None:
        for _ in range(self.decimation):
            self._mjw.step(self.m, self.d)

    def _launch(self, name: str, launches: Callable[[], None]) -> None:
        """Run ``launches`` (Warp kernels on every world): replayed from its graph where graphs are
        on, captured at the second call (the first compiles the kernels eagerly)."""
        wp = self._wp
        if self._use_graph and name in self._ran:
            if name not in self._graphs:
                self._graphs[name] = capture_graph(wp, self.device, launches)
            wp.capture_launch(self._graphs[name])
            return
        with wp.ScopedDevice(self.device):
            launches()
        self._ran.add(name)

    def _stand_where(self, rows: torch.Tensor) -> None:
        """Put the worlds where ``rows`` (N,) bool is set at the standing keyframe, time 0, no warm
        start, no overflow (the placeholder until the env resets them); a mask, not indices,
        so that no host read of ``rows`` is needed."""
        col = rows[:, None]
        self.qpos.copy_(torch.where(col, self._stand_qpos32, self.qpos))
        self.qvel.copy_(torch.where(col, self._stand_qvel32, self.qvel))
        self._time.masked_fill_(rows, 0.0)
        self._warmstart.masked_fill_(col, 0.0)
        self._overflow.masked_fill_(rows, 0)

    def reset_rows(self, env_ids: torch.Tensor, qpos: torch.Tensor, qvel: torch.Tensor) -> None:
        """Start worlds ``env_ids`` (M,) from ``qpos`` (M, 36), ``qvel`` (M, 35) at time 0 with
        their (re)randomised model rows; sensors recomputed at the stand targets, no wrench.
        Per-env model copies (one per world: the randomiser redraws them at resets) are copied
        in from the host ``MjModel`` copies; fewer, shared copies are drawn once and change only
        at a load (copied in once, then), so a reset copies none."""
        env_ids = env_ids.to(self.torch_device)
        rows = torch.zeros(self.num_envs, dtype=torch.bool, device=self.torch_device)
        rows[env_ids] = True
        self._stand_where(rows)
        self.qpos[env_ids] = qpos.to(self.torch_device, torch.float32)
        self.qvel[env_ids] = qvel.to(self.torch_device, torch.float32)
        self._sim["ctrl"][env_ids] = self._stand_ctrl
        self._sim["xfrc_applied"][env_ids] = 0.0
        if self._models_dirty:
            self._sync_models(range(len(self.copies)))
        elif len(self.copies) == self.num_envs > 1:  # per-env copies, redrawn at resets: their
            self._sync_models(env_ids.tolist())  # host rows, so the env ids go to the host
        self._refresh_rows(rows)

    def refresh_sensors(self, env_ids: torch.Tensor) -> None:
        """Recompute the sensor rows of ``env_ids`` (M,) from the current state and controls.
        ``mjw.forward`` runs every world; the other worlds keep their sensor rows."""
        rows = torch.zeros(self.num_envs, dtype=torch.bool, device=self.torch_device)
        rows[env_ids.to(self.torch_device)] = True
        self._refresh_rows(rows)

    def _refresh_rows(self, rows: torch.Tensor) -> None:
        """:meth:`refresh_sensors` of the worlds where ``rows`` (N,) bool is set."""
        sens = self._sim["sensordata"]
        keep = sens.clone()
        self._launch("forward", lambda: self._mjw.forward(self.m, self.d))
        sens.copy_(torch.where(rows[:, None], sens, keep))

    def _sync_models(self, rows) -> None:
        """Copy the randomised fields of model copies ``rows`` into their world rows. The values
        come from the host ``MjModel`` copies: a host-to-device copy, at resets only. The derived
        fields are left nominal, as MuJoCo C leaves them (no ``set_const``, module docstring)."""
        rows = list(rows)
        for field, view in self._model_views.items():
            values = np.stack([getattr(self.copies[r], field) for r in rows])
            view[rows] = torch.as_tensor(values, dtype=view.dtype).to(view.device)
        self._models_dirty = False

    def read(self) -> dict[str, Any]:
        """The robot fields of :class:`rl.envs.state.EnvState`: float32 tensors on
        :attr:`torch_device`, computed from the views (device-side copies, never the views)."""
        return robot_fields(self.layout, self.qpos, self.qvel, self._sim["sensordata"])

    @property
    def state(self) -> np.ndarray:
        """(N, nstate) FULLPHYSICS-layout rows (time, qpos, qvel filled; the rest the keyframe's):
        a read-only float64 snapshot, for readers written against MuJoCo C's ``env.state``."""
        lay = self.layout
        rows = np.tile(lay.stand_state, (self.num_envs, 1))
        rows[:, lay.time] = self._time.cpu().double().numpy()
        rows[:, lay.qpos] = self.qpos.double().cpu().numpy()
        rows[:, lay.qvel] = self.qvel.double().cpu().numpy()
        rows.flags.writeable = False
        return rows

    def state_dict(self) -> dict[str, Any]:
        """The worlds' state (qpos, qvel, time, warm start), sensor rows (tensors on
        :attr:`torch_device`) and divergence count."""
        return {
            "warp_qpos": self.qpos.clone(),
            "warp_qvel": self.qvel.clone(),
            "warp_time": self._time.clone(),
            "warp_qacc_warmstart": self._warmstart.clone(),
            "sensordata": self._sim["sensordata"].clone(),
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
        # copy_ takes a checkpoint's tensors from any device (run folders load onto the CPU)
        self.qpos.copy_(state["warp_qpos"])
        self.qvel.copy_(state["warp_qvel"])
        self._sim["sensordata"].copy_(state["sensordata"])
        self._time.copy_(state["warp_time"])
        self._warmstart.copy_(state["warp_qacc_warmstart"])
        self.diverged_counter.fill_(int(state["diverged_total"]))
        self._models_dirty = len(self.copies) > 1

    def close(self) -> None:
        """Drop the graphs and the device arrays."""
        self._graphs.clear()
        self._sim.clear()


def _model_copies(models: list[mujoco.MjModel]) -> list[mujoco.MjModel]:
    """The distinct models of ``models`` (N,), checked to follow the randomiser's rule (env i
    steps with copy i % G), which is how Warp reads a per-world field of G rows."""
    index: dict[int, int] = {}  # id of a distinct model -> its copy number (O(N), not O(N^2))
    copies: list[mujoco.MjModel] = []
    for model in models:
        if id(model) not in index:
            index[id(model)] = len(copies)
            copies.append(model)
    k = len(copies)
    if any(index[id(model)] != i % k for i, model in enumerate(models)):
        raise ValueError(
            "WarpPhysics: env i must step with model copy i % G (the Randomizer's rule); "
            "got another assignment of models to envs"
        )
    return copies
