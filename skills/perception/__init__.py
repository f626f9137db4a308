"""Perception from the eye-in-hand RGB-D camera (backend-agnostic: frames and poses only)."""

from skills.perception.heightmap import back_project_image
from skills.perception.upright import UprightPart, locate_upright_part

__all__ = ["UprightPart", "back_project_image", "locate_upright_part"]
