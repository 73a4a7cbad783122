import numpy as np

Array = np.ndarray

def edge_groups(lo: Array, hi: Array, n: int) -> tuple[Array, Array, Array, Array]: ...
def ring_slots(
    edges: Array, indptr: Array, indices: Array, diagonal: Array, forward: Array, backward: Array
) -> None: ...
