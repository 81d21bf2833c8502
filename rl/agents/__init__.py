"""Agents of A2CF: the VAE history encoder, the joint-action actor (motion + assist heads), the
rsl-rl PPO extension and the ONNX export of the motion policy."""
