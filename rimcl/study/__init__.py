"""Stage 8 — studies: the whole chain over cases, case files, Dask distribution and the study
summary.
"""
