"""Infrastructure every stage uses: errors, OpenCL devices and the kernel loader, file
provenance, memory guards.
"""
