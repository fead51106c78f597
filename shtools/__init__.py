"""shtools: low-frequency soft shadows with spherical harmonics (SHEXP), offline toolchain and baker."""

__version__ = "0.1.0"
