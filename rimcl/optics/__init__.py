"""Stage 2 — optics: cameras' ray fans, the Runge–Kutta–Nyström tracer on the OpenCL device,
its float64 reference and numba baseline, automatic choices.
"""
