"""Evaluations on the simulator: paper 000's centroid simulations (``gyrostar eval centroid``)."""
