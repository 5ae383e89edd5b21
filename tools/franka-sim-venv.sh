#!/usr/bin/env bash
# Make .venv-franka-sim at the repository root: franka-sim (a server of the libfranka network
# protocol on MuJoCo) in its own venv, because it pins numpy 1.26.4 and MuJoCo < 3.3. The
# Franka backend's tests (tests/test_franka_backend.py) and benchmark
# (benchmarks/deploy/franka_tracking.py) start the server from it; without it they skip.
# Every package is pinned (the versions these were checked with); nothing is downloaded at
# run time (rehabbot/deploy/franka_sim_server.py builds the robot model from the wheel's own URDF).
set -euo pipefail

cd "$(dirname "$0")/.."
python_bin=${PYTHON:-$(command -v python3.11 || command -v python3)}
"$python_bin" -m venv .venv-franka-sim
.venv-franka-sim/bin/pip install --quiet --disable-pip-version-check \
  franka-sim==1.1.7 numpy==1.26.4 mujoco==3.2.7 trimesh==5.2.0 robot_descriptions==3.3.0
.venv-franka-sim/bin/python -c "import franka_sim, mujoco; print('franka-sim', franka_sim.__version__ if hasattr(franka_sim, '__version__') else '1.1.7', 'MuJoCo', mujoco.__version__)"
