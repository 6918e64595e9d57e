"""A garment on a moving wearer: the arm-sleeve routes and the compression garment."""
