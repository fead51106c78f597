"""HDF5 assets: one module per kind, atomic writes, validated reads, versions.

See ``docs/formats.md`` for every kind's datasets, shapes and attributes.
"""

from shtools.data_formats._base import (
    KINDS,
    SCHEMAS,
    Asset,
    DatasetSpec,
    Schema,
    atomic_path,
    get_schema,
    read_asset,
    register,
    sha256_file,
    write_asset,
)

__all__ = [
    "KINDS",
    "SCHEMAS",
    "Asset",
    "DatasetSpec",
    "Schema",
    "atomic_path",
    "get_schema",
    "read_asset",
    "register",
    "sha256_file",
    "write_asset",
]
