"""Scan patterns: where and when pulses leave (a spinning LiDAR, a ray table, an airborne scanner and its presets) and a depth camera's pixels."""
