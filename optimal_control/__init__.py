"""Model-based oracle for the G1: wrench QP, references (walk, dance, backflip), bounds, artifacts."""
