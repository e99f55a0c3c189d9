"""What the robot is: geometry, material and magnetization, shared by every model."""

from . import presets
from .magnetization import Magnetization
from .rod import Rod
from .sections import Circle, Rectangle

__all__ = ["Rod", "Circle", "Rectangle", "Magnetization", "presets"]
