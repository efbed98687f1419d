"""Stage 1 — fields and media: the refractive-index field, its file format, the built-in flow
and importers, the fluids' refractive indices.
"""
