"""Old home of the batch operations: :mod:`o3d_lsmesh.app.ops`, ``app.files`` and ``app.tasks``."""

from .app.batch import parse_ops, resolve_options  # noqa: F401
from .app.files import READABLE, WRITABLE, read_mesh_file  # noqa: F401
from .app.ops import OPS, BatchOp, Option, TaskContext, register_op  # noqa: F401
from .app.tasks import run_task  # noqa: F401

__all__ = "OPS READABLE WRITABLE BatchOp Option TaskContext parse_ops read_mesh_file register_op resolve_options run_task"
__all__ = __all__.split()  # type: ignore[assignment]
