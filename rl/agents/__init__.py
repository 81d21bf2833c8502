"""Agents of A2CF: the VAE history encoder, the joint-action actor (motion + assist heads), the
rsl-rl PPO extension and the training modes."""

from rl.agents.models import ASSIST_ACTION_DIM, A2CFActor, JointActionHeads, MotionPolicy
from rl.agents.modes import MODES, ModeSpec, MotionOnlyEnv, get_mode
from rl.agents.ppo import A2CFPPO
from rl.agents.vae import EncoderOutput, HistoryEncoder

__all__ = [
    "ASSIST_ACTION_DIM",
    "A2CFActor",
    "A2CFPPO",
    "EncoderOutput",
    "HistoryEncoder",
    "JointActionHeads",
    "MODES",
    "ModeSpec",
    "MotionOnlyEnv",
    "MotionPolicy",
    "get_mode",
]
