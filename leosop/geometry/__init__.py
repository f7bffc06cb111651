"""Geometry of Doppler positioning shared by the stages above it: the measurement model and dilution of precision."""
