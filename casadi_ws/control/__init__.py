"""Inverse control: inputs that bring the end-effector to a target, or along a path of targets."""

from .inverse import FollowResult, ReachResult, ReachSettings, follow, reach

__all__ = ["FollowResult", "ReachResult", "ReachSettings", "follow", "reach"]
