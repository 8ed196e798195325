"""Lytro Illum and F01 captures: containers, raw images, calibration data, decoding."""
