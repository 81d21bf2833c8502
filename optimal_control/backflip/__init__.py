"""Multi-phase whole-body trajectory optimisation of a G1 backflip (CasADi + IPOPT).

Modules: :mod:`.config` (phases, limits, weights), :mod:`.sagittal` (the symmetric sagittal
parameterisation of the full 3-D model and its symbolic inverse dynamics), :mod:`.transcription`
(the NLP and the hand-designed initial guess), :mod:`.solve` (continuation, warm starts, caching),
:mod:`.audit` (energy and residual checks), :mod:`.playback` (MuJoCo physics check),
:mod:`.novice` (the explicit novice model: per-frame wrench QP at scaled torque limits) and
:mod:`.pipeline` (the `a2cf-mb solve-backflip` artifact).
"""
