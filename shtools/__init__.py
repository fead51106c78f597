"""shtools: low-frequency soft shadows with spherical harmonics (SHEXP).

An offline toolchain (sphere sets, trees, tables, lights) plus a per-vertex baker;
see README.md and docs/.
"""

__version__ = "0.1.0"
