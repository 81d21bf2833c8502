"""Reinforcement learning for the G1, in rooms that import one way (``tests/test_layout.py``)::

    rl.runs, rl.envs, rl.agents  <-  rl.tasks  <-  rl.a2cf, rl.evaluation  <-  rl.training  <-  rl.studies

:mod:`rl.envs` the batched simulator and its parts; :mod:`rl.tasks` one package per task, the
shared terms and the registry; :mod:`rl.agents` the networks, PPO and the ONNX export;
:mod:`rl.a2cf` the method (Algorithm 1, modes, coaches, warm start); :mod:`rl.runs` the run
folder; :mod:`rl.evaluation` the policy alone and sim2sim; :mod:`rl.training` the runner and
``train``; :mod:`rl.studies` comparisons and learning studies.

Kept free of imports so each submodule can be imported on its own.
"""
