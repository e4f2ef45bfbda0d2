"""Rigid-body motion of the camera and of scene objects: trajectories, their interpolation and generators."""
