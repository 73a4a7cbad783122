"""The array core: errors, validation, progress, connectivity, operators and the one solve gateway.

Nothing here imports Open3D or any module of this package above ``core``.
"""
