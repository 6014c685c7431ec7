"""Sensor measurement: displacement-sensor and load recordings to load-displacement curves."""
