"""Perception from the eye-in-hand RGB-D camera (backend-agnostic: frames and poses only)."""

from skills.perception.cloud import back_project
from skills.perception.upright import UprightPart, locate_upright_part

__all__ = ["UprightPart", "back_project", "locate_upright_part"]
