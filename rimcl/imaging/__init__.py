"""Stage 3 — imaging: tracer images on the sensor (renderer, sensor model, Mie weights),
centroids, and the two imaging engines (NumPy and OpenCL).
"""
