"""Controllers for flight near walls: cascaded PID, nominal MPC and SC-MPC, as Stable-Baselines3-style policies."""
