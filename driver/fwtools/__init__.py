"""Firmware tools: protocol generator, builds, host program and QEMU runners (``gyrostar fw``)."""
