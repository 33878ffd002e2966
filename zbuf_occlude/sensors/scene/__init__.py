"""The scene a sensor scans: its objects and files, their materials (reflectance, foliage), LAS classes and object shapes."""
