"""The A2CF method: Algorithm 1 and its measures, the modes, the coaches and the warm start."""
