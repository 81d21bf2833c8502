#!/usr/bin/env bash
# Every wheel a2cf-mb[gpu] needs, in one folder, for a machine with no package index (issue 22).
#
#   bash docs/results/gpu/make_wheels.sh WHEELS          # on a machine with an index
#   pip install --no-index --find-links WHEELS -e ".[gpu]"   # there
#
# Not for the lent GPU machine: its image has Python 3.12 and a CUDA torch that a wheel from here
# would shadow, and a call carries 64 MiB; make_payload.py builds what it lacks (docs/gpu.md).
#
# torch comes as the wheel pip picks here (this machine: the 2.13.0 CPU build, 192 MB); a GPU node
# needs a CUDA build of torch (several GB), from its own image or downloaded the same way. Measured on 2026-12-03 (Python 3.11, x86_64): 101
# wheels, 873 MB with the CPU torch; the largest are torch 192 MB, warp-lang 149 MB,
# example-robot-data 131 MB (the G1's meshes), casadi 93 MB, imageio-ffmpeg 68 MB.
# The build requirements of a2cf-mb itself (setuptools, wheel) are in the folder too: without
# them an offline editable install stops at "No matching distribution found for wheel".
# The wheels are for this machine's Python and platform: make the folder where they match.
set -euo pipefail
cd "$(dirname "$0")/../../.."
DIR=${1:?usage: make_wheels.sh WHEELS_FOLDER}
mkdir -p "$DIR"
python3 -m pip download -q -d "$DIR" "setuptools>=68" wheel
python3 -m pip download -q -d "$DIR" "torch==2.13.0" ".[gpu]"
python3 -m pip wheel -q --no-deps -w "$DIR" .
echo "$(ls "$DIR" | wc -l) wheels, $(du -sh "$DIR" | cut -f1) in $DIR; the largest:"
ls -S -s -h "$DIR" | sed -n 2,6p
