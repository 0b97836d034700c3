"""Policies for SoftGripperUnderwater-v0: the paper's scripted ramp, a reactive force controller, and PPO."""
