"""Stage 5 — particle tracking velocimetry: the synthetic measurement over frames and the
tracks' velocities and accelerations.
"""
