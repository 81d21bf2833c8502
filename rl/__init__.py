"""Reinforcement learning for the G1: batched MuJoCo environments (:mod:`rl.envs`), tasks
(:mod:`rl.tasks`), reward terms (:mod:`rl.rewards`), the A2CF assist machinery (:mod:`rl.assist`,
:mod:`rl.curriculum`), agents and the training runner.

Kept free of imports so each submodule can be imported on its own.
"""
