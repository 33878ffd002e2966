"""The scene a sensor scans: its objects and files, their materials (reflectance, foliage), LAS classes, object shapes and
the occluders a crop stands before its object."""
