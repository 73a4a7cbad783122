"""Old path of :mod:`o3d_lsmesh.app.batch` (``run``, ``collect_inputs``, ``summarize``, the op registry)."""

from .app.batch import OPS, BatchOp, Option, collect_inputs, local_cluster, register_op, run, summarize

__all__ = ["OPS", "BatchOp", "Option", "collect_inputs", "local_cluster", "register_op", "run", "summarize"]
