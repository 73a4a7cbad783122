"""The tuned constants of the fairing methods, each with the benchmark result that set it.

What each one weighs: docs/algorithms/scan_denoiser.rst, features.rst and constrained_fairing.rst;
the figures: the named files under benchmarks/results/.
"""

# --- the scan default (scan_fairing, scan_measure) ---------------------------------------------
# interior barycenter weight mu = SCAN_MU (g / sigma)^2 of a range scan: realscans_denoise.md (fitted on
# each object, scored on the other)
SCAN_MU = 0.06
SCAN_RIM_MU = 0.02  # rim weight mu w_t = SCAN_RIM_MU w, the least interior mu: realscans_denoise.md (14c64a8)
SLIVER_QUALITY = 0.05  # triangle quality (1 equilateral) of a sliver: realscans_denoise.md (slivers column)
SCAN_MEMBRANE = 0.45  # membrane weight lambda of a range scan's energy: realscans_denoise.md
SCAN_BOUNDARY_WEIGHT = 0.1  # least rim weight relative to the interior's: realscans_denoise.md (w 0.10-0.13)
SCAN_RIM_RATIO = (0.3, 0.6)  # rim data weights of scan likeness 1 and 0: realscans_denoise.md, denoise.md
SCAN_BOUNDARY_FRACTION = (0.01, 0.03)  # boundary fractions of scan likeness 0 and 1: realscans_denoise.md
# mu = NOISE_MU_SCALE (g / sigma)^NOISE_MU_POWER for independent noise, clipped to MU_RANGE: denoise.md
# (bunny, screwdriver, feline at 0.2 and 0.5 edge noise)
NOISE_MU_SCALE = 0.8
NOISE_MU_POWER = 2.5
MU_RANGE = (3e-3, 1.0)
SCAN_ITERATIVE_VERTICES = 5_000  # solver="auto" takes IC(0) CG from here: realscans_denoise_speed.md
SCAN_REDUCTION = 1e-4  # each iterative solve's residual reduction: realscans_denoise_speed.md (vs exact)
RIM_RINGS = 3  # relax_rim's band in edges from the rim, and its sweeps: realscans_denoise.md (slivers column)
# measured_noise forms the 2-ring pattern in NOISE_BLOCKS blocks of at least NOISE_BLOCK rows over at most
# NOISE_ROWS vertices (memory and time, not quality): realscans_denoise_speed.md (1.4M-vertex row)
NOISE_BLOCKS = 16
NOISE_BLOCK = 1 << 16
NOISE_ROWS = 1 << 14

# --- the paper's operators (barycenter) -------------------------------------------------------
DEFAULT_MU = 0.03  # penalty weight mu of method="global": denoise.md (mu in {0.01, 0.03, 0.1, 0.3, 1})
BLOCK_ROWS = 1 << 13  # rows per block of the local operator's assembly: scale.md (local fairing rows)

# --- the feature-preserving denoiser (features) -----------------------------------------------
SIGMA_R = 0.35  # range kernel width on unit-normal differences (Zhang et al.'s): features_denoise.md
# the passes stop when the median filtered dihedral angle of pass k is above CONCENTRATION times pass k // 2's,
# at most MAX_PASSES: features_passes_study.md (leave-one-mesh-out)
CONCENTRATION = 0.75
MAX_PASSES = 35
VERTEX_STEPS = 10  # vertex steps after each filter pass (the reference code's): features_denoise.md
CREASE_ANGLE = 30.0  # degrees between denoised face normals of a crease: features_denoise.md (crease recall)
# method="auto" (the default) has no constant of its own: the feature mode where the stop above comes at
# MAX_PASSES, the scan energy where it comes before (features_denoise.md: the choice on every mesh)
