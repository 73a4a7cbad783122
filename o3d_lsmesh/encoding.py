"""Old path of :mod:`o3d_lsmesh.lsmesh.encoding`."""

from .lsmesh.encoding import decode_geometry, encode_geometry, iter_decode_geometry

__all__ = ["decode_geometry", "encode_geometry", "iter_decode_geometry"]
