"""Stage 4 — the scene: a TOML scene parsed once into the typed configuration every later stage
takes.
"""
