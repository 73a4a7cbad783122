"""Tuned constants of the solve gateway (:mod:`~o3d_lsmesh.core.solve`, :mod:`~o3d_lsmesh.core._iterative`).

Each names the benchmark result that set it; the figures are there and in docs/algorithms/solvers.rst.
The modules read them as ``tuning.NAME`` at use time.
"""

# CG's relative residual per column: within 3e-8 of CHOLMOD at 200k-1M vertices (benchmarks/results/scale.md)
DEFAULT_TOLERANCE = 1e-9
# share of the available memory a direct factor may take under backend="auto" (benchmarks/results/scale.md)
BUDGET_FRACTION = 0.5
# constant-mode strength below which round-off moves a component by 1e-6 of |x| (float64 analysis, no benchmark)
NEGLIGIBLE = 1e-10
# CHOLMOD factor entries per n log2 n at 19 entries a row, torus grids 20k-500k (benchmarks/results/scale.md)
FILL_PER_ROW_LOG = 11.0
# largest |a_ij - a_ji| over the largest entry taken as symmetric: above assembly round-off (no benchmark)
SYMMETRY_TOLERANCE = 1e-10
# right-hand sides this close to the span of earlier ones are recycled (benchmarks/results/no_cholmod.md)
RECYCLE_TOLERANCE = 1e-13
# solved right-hand sides kept for recycling: greedy selection's span is four (benchmarks/results/no_cholmod.md)
RECYCLED = 8
# IC(0) set-up work per matrix entry past which the V-cycle runs instead (benchmarks/results/realscans_denoise_speed.md)
IC_WORK = 16
# IC(0)'s first diagonal shift after a breakdown, doubling (benchmarks/results/realscans_denoise_speed.md)
FIRST_SHIFT = 1e-3
# shifts tried after the first breakdown, the last far past diagonal dominance (no benchmark)
MAX_SHIFTS = 20
# unknowns at which AMG stops coarsening and factors (benchmarks/results/scale.md)
COARSE_UNKNOWNS = 500
# aggregation strength threshold: keeps the 1-ring of an LS-mesh normal matrix (benchmarks/results/scale.md)
STRENGTH = 0.1
# average row reach past which the iterative path renumbers by reverse Cuthill-McKee (benchmarks/results/scale.md)
LOCAL_SPAN = 16384
# rows per block of the parallel Gauss-Seidel sweeps, at most SWEEP_BLOCKS blocks (benchmarks/results/scale.md)
ROWS_PER_SWEEP_BLOCK = 65536
SWEEP_BLOCKS = 32
# solve_spd's dense Cholesky up to this many unknowns, hole patches (benchmarks/results/fill_holes.md)
DENSE_UNKNOWNS = 120
# conjugate-gradient iterations before ConvergenceError (a bound, no benchmark)
MAX_ITERATIONS = 5000
