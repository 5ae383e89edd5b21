"""The paper's Listing 1: one episode of ``rehabbot/rehab-reach-v0`` with random actions in
MuJoCo's viewer. It opens a window, so it needs a display; on a headless machine run
``xvfb-run -a python examples/listing1_visualize.py``."""

# The listing is kept exactly as printed (import grouping, comment spacing, unused import).
# ruff: noqa: I001, F401

import gymnasium as gym
import rehabbot # registers env IDs

env = gym.make("rehabbot/rehab-reach-v0",
render_mode="human")
obs, info = env.reset(seed=0)

done = False
while not done:
    action = env.action_space.sample()
    obs, reward, terminated, truncated, info = env.step(action)
    done = terminated or truncated
env.close()
