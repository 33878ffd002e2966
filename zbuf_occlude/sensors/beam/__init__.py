"""The beam of a pulsed LiDAR and its physics: its fields and checks, footprint, echoes, waveform, attenuation, the echo energy with the scene, and the adaptive cast with its kernel."""
