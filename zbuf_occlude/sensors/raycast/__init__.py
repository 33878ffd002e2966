"""Ray casts by backend: Embree (exact, CPU) and the moderngl z-buffer with exact candidate tests."""
