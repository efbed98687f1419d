"""Stage 7 — particle image velocimetry: full-frame image pairs, window-deformation cross-
correlation, PIV studies.
"""
