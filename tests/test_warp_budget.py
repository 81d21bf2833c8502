"""What an env step costs a GPU besides its kernels: host waits and eager Warp launches, counted on
the CPU (issue 35).

On a GPU every read of a device value on the host (``t.item()``, ``float(t)``, ``bool(t)``,
``t.tolist()``, ``t.nonzero()``, ``t.cpu()``, a boolean-mask index) waits for the device, and every
Warp kernel launched outside a graph costs a launch from Python (mujoco_warp's ``forward`` is 166 of
them, ``set_const`` 769). torch's ``set_sync_debug_mode`` only works on CUDA, so
:class:`HostReads` counts the calls to those Tensor methods instead, and :class:`WarpLaunches`
the calls to ``wp.launch`` (and its relatives): on the CPU the same code makes the same calls.
Each count has a ceiling below. ``tests/test_warp_physics.py`` holds the physics' parity tests.
"""

from __future__ import annotations

import contextlib
import importlib.util
from collections import Counter
from collections.abc import Iterator

import pytest
import torch

from rl.envs.host_values import to_host
from rl.envs.task_schema import quiet
from rl.tasks.registry import make_env
from rl.tasks.stand.task import STAND

needs_warp = pytest.mark.skipif(
    importlib.util.find_spec("mujoco_warp") is None,
    reason="mujoco-warp is not installed (pip install -e '.[gpu]')",
)
SYNC_METHODS = ("item", "tolist", "numpy", "cpu", "nonzero", "__bool__", "__int__", "__float__")
"""Tensor methods that read a device value on the host (each a wait for a GPU)."""
WARP_LAUNCHES = ("launch", "launch_tiled", "copy")
"""Warp calls that launch work eagerly (inside a graph capture they are recorded instead)."""
STEPS_WITHOUT_RESET_MAX_READS = 1
"""The env's one batch of host values (log scalars, fault flags, done mask) per step."""
STEP_WITH_RESET_MAX_READS = 3
"""A step where an env of a quiet task resets (measured 3): the batch, and the skill window's
counted episodes (a boolean-mask index) and new mean. (Per-env randomisation adds the parameter
rows and ids for the host ``MjModel`` copies, 7 in all; pushes add their due rows.)"""


class HostReads:
    """Counts host reads of tensors (:data:`SYNC_METHODS` and boolean-mask indexing) while
    :attr:`active`; :attr:`calls` says which method was called how often."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.active = False
        self.calls: Counter[str] = Counter()
        self._host: list[torch.Tensor] = []  # what ``.cpu()`` returned while counting (kept alive)
        for name in SYNC_METHODS:
            monkeypatch.setattr(
                torch.Tensor, name, self._counted(name, getattr(torch.Tensor, name))
            )
        for name in ("__getitem__", "__setitem__"):
            original = getattr(torch.Tensor, name)
            monkeypatch.setattr(torch.Tensor, name, self._mask_index(name, original))

    def _counted(self, name: str, original):
        def wrapper(tensor, *args, **kwargs):
            host = {h.untyped_storage().data_ptr() for h in self._host}
            if self.active and tensor.untyped_storage().data_ptr() not in host:
                self.calls[name] += 1
            result = original(tensor, *args, **kwargs)
            if self.active and name == "cpu":  # a host copy on a GPU: reading it waits no more
                self._host.append(result)
            return result

        return wrapper

    def _mask_index(self, name: str, original):
        def wrapper(tensor, index, *args):
            items = index if isinstance(index, tuple) else (index,)
            masks = [i for i in items if isinstance(i, torch.Tensor) and i.dtype == torch.bool]
            if self.active and masks:
                self.calls[f"{name}[bool mask]"] += 1
            return original(tensor, index, *args)

        return wrapper

    @property
    def total(self) -> int:
        """Host reads counted so far."""
        return sum(self.calls.values())

    @contextlib.contextmanager
    def counting(self) -> Iterator[None]:
        """Count inside this block."""
        self.active = True
        try:
            yield
        finally:
            self.active = False
            self._host.clear()

    @contextlib.contextmanager
    def paused(self) -> Iterator[None]:
        """Do not count inside this block (e.g. the MuJoCo C physics, whose state is on the host)."""
        was, self.active = self.active, False
        try:
            yield
        finally:
            self.active = was


class WarpLaunches:
    """Counts Warp's eager launches (:data:`WARP_LAUNCHES`) made while :attr:`active`."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        import warp as wp

        self.active, self.count = False, 0
        for name in WARP_LAUNCHES:
            monkeypatch.setattr(wp, name, self._counted(getattr(wp, name)))

    def _counted(self, original):
        def wrapper(*args, **kwargs):
            self.count += self.active
            return original(*args, **kwargs)

        return wrapper


def test_to_host_reads_what_float_and_nonzero_read() -> None:
    """One transfer gives the floats ``float(t)`` gives (float32 and integer tensors alike, host
    numbers passed through, key order kept) and the indices ``nonzero`` gives."""
    gen = torch.Generator().manual_seed(0)
    x = torch.rand(1000, generator=gen)
    values = {"mean": x.mean(), "host": 3, "count": (x > 0.5).sum(), "tiny": x.min() * 1e-30}
    rows = x > 0.9
    host, ids = to_host(values, rows)
    assert list(host) == list(values)
    assert host == {k: float(v) for k, v in values.items()}
    assert all(type(v) is float for v in host.values())
    assert torch.equal(ids, rows.nonzero().flatten())


def test_a_mujoco_env_step_reads_the_host_once_besides_its_physics(monkeypatch) -> None:
    """The env's own parts (everything but the MuJoCo C physics, whose state lives on the host)
    read device values once per step without a reset: its batch of host values."""
    env = make_env(quiet(STAND), 4, num_threads=1)
    reads = HostReads(monkeypatch)
    for name in ("step", "reset_rows"):  # the physics' own reads are host work on MuJoCo C
        original = getattr(env.physics, name)

        def paused(*args, _original=original, **kwargs):
            with reads.paused():
                return _original(*args, **kwargs)

        monkeypatch.setattr(env.physics, name, paused)
    try:
        zeros = torch.zeros(4, 35)
        env.step(zeros)
        with reads.counting():
            for _ in range(3):
                _, _, dones, _ = env.step(zeros)
        assert not dones.any()
        assert reads.total <= 3 * STEPS_WITHOUT_RESET_MAX_READS, reads.calls
        env.physics.qpos[1, 2] = 0.2  # a fall: one env resets in the next step
        with reads.counting():
            _, _, dones, _ = env.step(zeros)
        assert dones.tolist() == [False, True, False, False]
        assert reads.total <= 3 + STEP_WITH_RESET_MAX_READS, reads.calls  # 3: the steps above
    finally:
        env.close()


@contextlib.contextmanager
def warp_env_with_graphs(monkeypatch: pytest.MonkeyPatch, num_envs: int, task=None):
    """A Warp env on Warp's CPU device whose step and reset ``forward`` replay Warp graphs (as on a
    CUDA device with the memory pool on)."""
    from rl.envs import warp_physics

    monkeypatch.setattr(warp_physics, "cuda_graphs_usable", lambda wp, device: True)
    env = make_env(task if task is not None else quiet(STAND), num_envs, backend="warp")
    try:
        yield env
    finally:
        env.close()


@pytest.mark.slow
@needs_warp
def test_a_warp_env_step_launches_nothing_eagerly_and_reads_the_host_once(monkeypatch) -> None:
    """After warm-up (the first step and the first reset compile the kernels, the second capture
    them), a step and a reset replay graphs only (0 eager Warp launches), and the host reads stay
    within their ceilings."""
    with warp_env_with_graphs(monkeypatch, 3) as env:
        zeros = torch.zeros(3, 35)
        for _ in range(2):
            env.physics.qpos[0, 2] = 0.2  # a fall, hence a reset: warms the forward graph up
            env.step(zeros)
        assert set(env.physics._graphs) == {"step", "forward"}
        reads, launches = HostReads(monkeypatch), WarpLaunches(monkeypatch)
        launches.active = True
        with reads.counting():
            for _ in range(3):
                _, _, dones, _ = env.step(zeros)
        assert not dones.any()
        assert launches.count == 0
        assert reads.total <= 3 * STEPS_WITHOUT_RESET_MAX_READS, reads.calls
        env.physics.qpos[1, 2] = 0.2
        with reads.counting():
            _, _, dones, _ = env.step(zeros)
        assert dones.tolist() == [False, True, False]
        assert launches.count == 0
        assert reads.total <= 3 + STEP_WITH_RESET_MAX_READS, reads.calls  # 3: the steps above


@pytest.mark.slow
@needs_warp
def test_graph_replays_equal_eager_launches_and_see_model_edits(monkeypatch) -> None:
    """The same randomised env, eager and replayed from graphs on Warp's CPU device, steps to the
    same states bit for bit, through resets whose new payloads are written into the per-world
    model arrays after the capture (the replays read them in place)."""
    eager = make_env(STAND, 3, backend="warp")
    try:
        with warp_env_with_graphs(monkeypatch, 3, STAND) as graphed:
            assert not eager.physics._use_graph and graphed.physics._use_graph
            gen = torch.Generator().manual_seed(5)
            masses = []
            for step in range(6):
                actions = 0.3 * torch.randn(3, 35, generator=gen)
                for env in (eager, graphed):
                    if step in (1, 3):  # world 0 falls: a reset with a new payload
                        env.physics.qpos[0, 2] = 0.2
                    env.step(actions)
                for name in ("qpos", "qvel"):
                    assert torch.equal(getattr(graphed.physics, name), getattr(eager.physics, name))
                assert torch.equal(
                    graphed.physics._sim["sensordata"], eager.physics._sim["sensordata"]
                )
                masses.append(graphed.physics._model_views["body_mass"][0].clone())
            assert "forward" in graphed.physics._graphs and "step" in graphed.physics._graphs
            assert not torch.equal(masses[1], masses[-1])  # the payload changed after capture
    finally:
        eager.close()
