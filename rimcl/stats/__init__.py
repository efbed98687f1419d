"""Stage 6 — statistics and figures: errors against truth and reference, intervals, tables and
matplotlib figures.
"""
