"""Type stub of the compiled hierarchy levels (``collapse.pyx``)."""

from collections.abc import Callable
from typing import Any

import numpy as np

def collapse_levels(
    vertices: np.ndarray,
    triangles: np.ndarray,
    *,
    alpha: float,
    beta: float,
    max_normal_angle: float,
    min_quality: float,
    max_tries: int,
    min_vertices: int = ...,
    max_levels: int | None = ...,
    report: Callable[[int], Any] | None = ...,
) -> tuple[np.ndarray, list[tuple[np.ndarray, ...]]]: ...
