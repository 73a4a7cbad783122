"""The tuned constants of the fairing methods, each with the benchmark result that set it.

What each one weighs is explained in docs/algorithms/scan_denoiser.rst, features.rst and
constrained_fairing.rst; the figures are in the named files under benchmarks/results/.
"""

# --- the scan default (scan_fairing, scan_measure) ---------------------------------------------
#: Interior barycenter weight ``mu = SCAN_MU (g / sigma)^2`` of a range scan.
# set by benchmarks/results/realscans_denoise.md (fitted on each object, scored on the other)
SCAN_MU = 0.06
#: Rim barycenter weight ``mu w_t = SCAN_RIM_MU w``; also the interior's least ``mu``.
# set by benchmarks/results/realscans_denoise.md (coarse-scan row: commit 14c64a8)
SCAN_RIM_MU = 0.02
#: Triangle quality (1 equilateral) below which a triangle is a sliver.
# set by benchmarks/results/realscans_denoise.md (slivers column)
SLIVER_QUALITY = 0.05
#: Membrane weight ``lambda`` of a range scan's energy.
# set by benchmarks/results/realscans_denoise.md
SCAN_MEMBRANE = 0.45
#: Least barycenter weight of the rim triangles relative to the interior's.
# set by benchmarks/results/realscans_denoise.md (measured w 0.10-0.13)
SCAN_BOUNDARY_WEIGHT = 0.1
#: Rim data weights at which the scan likeness is 1 and 0.
# set by benchmarks/results/realscans_denoise.md and benchmarks/results/denoise.md (the two ends)
SCAN_RIM_RATIO = (0.3, 0.6)
#: Boundary-vertex fractions at which the scan likeness is 0 and 1.
# set by benchmarks/results/realscans_denoise.md (range scans: 7-13% boundary vertices)
SCAN_BOUNDARY_FRACTION = (0.01, 0.03)
#: ``mu = NOISE_MU_SCALE (g / sigma)^NOISE_MU_POWER`` for independent noise, clipped to ``MU_RANGE``.
# set by benchmarks/results/denoise.md (bunny, screwdriver, feline at 0.2 and 0.5 edge noise)
NOISE_MU_SCALE = 0.8
NOISE_MU_POWER = 2.5
MU_RANGE = (3e-3, 1.0)
#: Vertex count from which ``solver="auto"`` solves the scan energy by IC(0)-preconditioned CG.
# set by benchmarks/results/realscans_denoise_speed.md
SCAN_ITERATIVE_VERTICES = 5_000
#: Each iterative solve stops at this fraction of its starting residual.
# set by benchmarks/results/realscans_denoise_speed.md (error against the exact minimizer)
SCAN_REDUCTION = 1e-4
#: ``relax_rim`` relaxes the vertices up to this many edges from the rim, by as many sweeps.
# set by benchmarks/results/realscans_denoise.md (slivers column)
RIM_RINGS = 3
#: ``measured_noise`` forms the 2-ring pattern in this many blocks of at least ``NOISE_BLOCK`` rows
#: and averages over at most ``NOISE_ROWS`` vertices (memory and time, not quality).
# set by benchmarks/results/realscans_denoise_speed.md (1.4M-vertex row)
NOISE_BLOCKS = 16
NOISE_BLOCK = 1 << 16
NOISE_ROWS = 1 << 14

# --- the paper's operators (barycenter) -------------------------------------------------------
#: Penalty weight ``mu`` of ``method="global"``.
# set by benchmarks/results/denoise.md (mu in {0.01, 0.03, 0.1, 0.3, 1})
DEFAULT_MU = 0.03
#: Rows per block of the local operator's assembly (temporaries of a few megabytes).
# set by benchmarks/results/scale.md (local fairing rows)
BLOCK_ROWS = 1 << 13

# --- the feature-preserving denoiser (features) -----------------------------------------------
#: Width of the range kernel on unit-normal differences (Zhang et al.'s default).
# set by benchmarks/results/features_denoise.md
SIGMA_R = 0.35
#: Filter passes per unit of measured noise (in mean edge lengths).
# set by benchmarks/results/features_denoise.md (leave-one-mesh-out)
PASSES_PER_NOISE = 60.0
#: Vertex steps after each filter pass (the reference implementation's count).
# set by benchmarks/results/features_denoise.md
VERTEX_STEPS = 10
#: Angle (degrees) between two faces' denoised normals above which their edge is a crease.
# set by benchmarks/results/features_denoise.md (crease recall)
CREASE_ANGLE = 30.0
