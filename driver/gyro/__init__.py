"""Gyro devices: one interface (:class:`GyroDevice`), BMI088 and L3GD20H drivers, numba conversion."""

from .base import FifoGyro, GyroDevice
from .bmi088 import Bmi088Gyro
from .convert import (
                      FLAG_GAP,
                      FLAG_SAT_X,
                      FLAG_SAT_Y,
                      FLAG_SAT_Z,
                      FLAG_SATURATED,
                      FLAG_STUCK,
                      FLAG_STUCK_AXIS,
                      FLAG_TIME_EST,
)
from .l3gd20h import L3gd20hGyro
from .samples import GyroSamples

__all__ = ["GyroDevice", "FifoGyro", "Bmi088Gyro", "L3gd20hGyro", "GyroSamples", "FLAG_GAP", "FLAG_SAT_X",
           "FLAG_SAT_Y", "FLAG_SAT_Z", "FLAG_SATURATED", "FLAG_STUCK", "FLAG_STUCK_AXIS", "FLAG_TIME_EST"]
