"""Deployment without the training code: :mod:`a2cf_mb.deploy.run_bundle` plays an exported
policy bundle (``policy.onnx``, ``policy.json``, ``reference.npz``) in MuJoCo from its folder alone."""
