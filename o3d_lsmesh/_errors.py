"""Exception and warning classes of o3d_lsmesh."""

__all__ = ["ConvergenceError", "O3DLSMeshWarning", "SingularSystemError"]


class SingularSystemError(ValueError):
    """The linear system cannot be solved as posed.

    Raised before factoring when it is cheap to see (a connected component
    without any constraint), otherwise translated from the factorization.
    """


class O3DLSMeshWarning(UserWarning):
    """A warning about a fallback or about data that was dropped."""


class ConvergenceError(RuntimeError):
    """An iterative solve did not reach its tolerance within its iteration limit."""
