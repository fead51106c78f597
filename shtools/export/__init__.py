"""Exports of a bake: one module per format, as ``shtools export`` writes them.

- :mod:`shtools.export.ply` — vertex-coloured PLY (sRGB-encoded colours);
- :mod:`shtools.export.gltf` — GLB with linear ``COLOR_0`` and raw ``_RADIANCE``;
- :mod:`shtools.export.animated` — one animated GLB of a frame range (colour morph
  targets, node TRS);
- :mod:`shtools.export.usd` — a time-sampled USD stage;
- :mod:`shtools.export.png` — CPU previews: a frame, a contact sheet, an animated GIF;
- :mod:`shtools.export.raster` — the NumPy z-buffer rasteriser behind the previews;
- :mod:`shtools.export.tonemap` — exposure, tone curves, sRGB encoding;
- :mod:`shtools.export.writer` — ``export_bake(bake, path, ...)`` dispatching on the suffix.
"""
