"""Type stub of the compiled hierarchy kernel (``_kernel.pyx``)."""

from collections.abc import Callable
from typing import Any

import numpy as np

def hierarchy(
    positions: np.ndarray,
    triangles: np.ndarray,
    lock: np.ndarray,
    alpha: float,
    beta: float,
    min_vertices: int,
    max_levels: int,
    cos_sq: float,
    min_quality: float,
    max_tries: int,
    lock_fans: bool,
    report: Callable[[int], Any],
) -> list[tuple[np.ndarray, ...]]: ...
