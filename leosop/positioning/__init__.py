"""Positioning: Doppler least squares and dilution of precision."""
