"""PPO agents (Stable-Baselines3) trained on the Wall Inspector tasks."""
