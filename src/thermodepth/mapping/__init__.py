"""3D thermal mapping from a moving rig: trajectory, fused volume, model."""
