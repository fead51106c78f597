"""Bounds of a shadow field's sampling parameters, inclusive ``(lo, hi)``.

One place for both checks: :meth:`shtools.fields.FieldParameters.validate` (Python
callers) and the option types of ``shtools field sample`` (its ``--help`` shows them).
A module of its own so that the command line reads them without importing the field
sampler.
"""

#: Radial shells of a field (``--shells``).
SHELLS = (1, 256)
#: Direction-map size of a field's shells (``--map``).
MAP_SIZE = (4, 1024)
#: Bits of a quantized coefficient (``--bits``; the asset stores at most 8).
BITS = (1, 8)
#: Direction-map resolution of a shell (``--resolution``, a power of two; the smallest
#: of its adaptive subdivision, ``--min-resolution``, any power of two up to it).
RESOLUTION = (2, 4096)
