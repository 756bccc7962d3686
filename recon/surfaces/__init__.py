"""Surfaces from point clouds: the registry of methods (``methods/``, one module per method),
normals, preparation of a cloud, and one method run safely in its own process (``isolation``)."""
