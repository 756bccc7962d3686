"""Tolerances and defaults of the metrics package, each with where its number comes from.

Lengths are never absolute: every length default is a fraction of the truth mesh's bounding-box
diagonal, so a 300 m asteroid and a 20 m satellite are scored on the same footing.
"""

# --------------------------------------------------------------------------- score()

# Distance threshold tau of precision, recall, F-score and coverage, as a fraction of the truth
# bounding-box diagonal. 1 % is the usual "F-score@1%" of mesh-reconstruction benchmarks. For the
# paper's targets it is 0.2 m on the 20 m satellite (about 2 sigma of the LRF's 0.3 m 3-sigma
# range noise, so a noisy but complete cloud still scores high recall and F measures holes and
# gross errors rather than sensor noise) and 6.6 m on the 665 m-diagonal ellipsoid. At 0.5 % the
# threshold would sit at 1 sigma of that noise and F would mostly measure the noise.
TAU_FRACTION = 0.01

# Points sampled on the truth surface (uniformly by area) for completeness and recall when the
# caller gives a sample count (``score(..., n_test_samples=...)``): recall is then a proportion
# of these, its standard error at most 0.5 / sqrt(n) = 0.0011. A score to a precision (no count
# given, ``metrics.precision``) takes its truth samples first from this draw (seed [seed, 1]),
# as many as its precision needs.
TRUTH_SAMPLES = 200_000

# Points sampled on a test *mesh* (uniformly by area) to measure its accuracy, when a count is
# given. A score to a precision draws this many too (the same points, seed ``seed``): the edge
# metric runs on all of them (its value depends on the sampling density: a point within the
# tolerance of a truth edge), the accuracy on the first as many as its precision needs.
TEST_MESH_SAMPLES = 200_000

# Coverage quadrature: each truth face is split into s**2 congruent sub-triangles whose centroids
# are tested against tau; s is chosen per face so the sub-triangles have about total_area /
# COVERAGE_POINTS of area each (and s >= 1, so every face is tested at least once). 4e5 points
# keep the query under ~0.5 s and give ~9 points per face on a 49k-face asteroid model. The
# fixed-count default; a score to a precision sizes it with ``precision.lattice_size`` (10,000 at
# the default precision, i.e. one point per face on the demo asteroid's 20,480 faces).
COVERAGE_POINTS = 400_000
# Cap on s, so one face that holds most of the area cannot ask for an unbounded lattice.
COVERAGE_MAX_SUBDIVISION = 512
# Memory a score takes per coverage lattice point, at its peak: the point (24 B) and its face
# (8 B), kept; their copies while the lattice is sorted by face; the points joined with the
# truth samples in Morton order, their distances and the nearest-neighbour query's own arrays.
# Measured 150-230 B per point (peak resident memory of ``score`` and ``score_stream`` at 2.5 to
# 6.8 million points, to a count and to a precision); 240 B to spare.
LATTICE_BYTES_PER_POINT = 240
# Most memory a coverage lattice may take (LATTICE_BYTES_PER_POINT a point): a precision or a
# count that asks more is refused before any work (``score._Setup``). 4 GiB holds about 18
# million points, whose coverage standard error is at most 0.5 / sqrt(1.8e7) = 1.2e-4, four
# times below recall's at MAX_SAMPLES (4.9e-4): a finer lattice would state a coverage no other
# score matches, while its memory grows without bound (a precision of 1e-9 puts 512**2 points
# on every face). 4 GiB leaves the rest of a score room on a machine of 8 GB.
COVERAGE_MAX_BYTES = 4 << 30

# Seed used when the caller gives none: scores are reproducible by default.
SEED = 0

# Warn (ScaleMismatchWarning) when the bounding-box diagonals of test and truth differ by more
# than this factor: 100x is beyond any plausible reconstruction error and catches km against m
# (a factor of 1000) with margin.
SCALE_MISMATCH_RATIO = 100.0

# --------------------------------------------------------------------------- distances

# Points handled per block in the exact-distance post-processing: 2**16 points keep the per-block
# temporaries (~30 arrays of 512 KB) to ~15 MB and give the 2 threads 16 blocks per million points.
DISTANCE_BLOCK = 1 << 16
# A face whose doubled area is below this fraction of (mesh diagonal)**2 is treated as degenerate
# (a segment or a point): ~50 float64 epsilons of the squared scale, far below any real facet.
DEGENERATE_AREA_FRACTION = 1e-14
# A neighbouring triangle whose vertices rise less than this fraction of the mesh diagonal above a
# face's plane is treated as lying behind it (coplanar neighbours). A neighbour ignored this way
# can be closer than the candidate by at most this much, an absolute error of 1e-12 of the
# diagonal: the absolute tolerance of the brute-force tests, 1000x below their 1e-9 relative one
# for distances of the order of the diagonal.
COPLANAR_FRACTION = 1e-12

# --------------------------------------------------------------------------- edge metric

# Neighbourhood size k (the point itself included) of the surface variation. Pauly, Gross and
# Kobbelt (2002) use k of 10..30. k counts points, so the neighbourhood radius follows the local
# density and the edge test has no length scale. `benchmarks/bench_edge_metric.py --calibrate`
# measures, on 60,000 uniform points, the fraction of points flagged by the leave-one-out rule
# with the default threshold (below) on a crease and on a plane with Gaussian noise:
#       k    30-deg crease   90-deg crease   plane + noise of 5 % / 10 % of the point spacing
#       8        0.55            0.76              0.10 / 0.36
#      16        0.64            0.88              0.013 / 0.18
#      32        0.68            0.99              0.000 / 0.05
# and a noise-free sphere of radius ~10 neighbourhood radii flags no point at any k. 16 sees the
# default feature angle (30 degrees) and flags few points of a plane whose noise is 5 % of the
# spacing, with half the neighbourhood radius (finer detail, thinner plates) and half the k-NN
# cost of k = 32.
EDGE_K = 16
# Leave-one-out rule (the paper's): a point is an edge point when removing it from its own
# neighbourhood lowers sigma = l0 / (l0 + l1 + l2) by more than this, at k = EDGE_K. A crease
# point's drop scales as about 1 / k (median 0.0081, 0.0043, 0.0023 at k = 8, 16, 32 on a
# 90-degree crease), so for another k the default threshold is this times EDGE_K / k.
EDGE_DROP_THRESHOLD = 0.0005
# Plain Pauly rule: a point is an edge point when its sigma exceeds this. A flat disc has 0, a
# 90-degree crease through the centre ~0.1, the upper bound (isotropic) is 1/3; 0.03 flags the
# central points of creases of 60 degrees and more.
EDGE_SIGMA_THRESHOLD = 0.03
# Truth feature edges: interior mesh edges whose faces' normals differ by more than this angle.
# 30 degrees is the classic "sharp edge" / auto-smooth threshold (Blender, MeshLab), and the
# angle the leave-one-out rule is calibrated to see (table above: 64 % of a 30-degree crease's
# points at k = 16). The weighted edge metric asks an edge point within the tolerance of a
# feature edge, and only a test point within it of a gentler edge (the ~2-5 degree facet edges
# of a triangulated ellipsoid; a point on a 5 / 10 / 20-degree crease lowers sigma by a median
# 2e-5 / 8e-5 / 3e-4 at k = 16), which no threshold can tell from curvature or noise; the
# feature-edge variant counts feature edges only.
FEATURE_ANGLE_DEG = 30.0
# Truth edges flatter than this (degrees) are the diagonals of flat regions, not edges of the
# shape: the weighted edge metric leaves them out instead of sampling them. Two coplanar faces
# give an angle of ~1e-6 deg in float64; an edge at 0.001 deg weighs 2e-5 of its length, less
# than 1/1000 of a 2 deg facet edge of the paper's ellipsoid.
FLAT_EDGE_DEG = 1e-3
# Edge tolerance as a fraction of the truth bounding-box diagonal: a detected edge point within
# it of a truth feature edge is a true edge point, and a truth edge with a detected edge point
# within it is found. Same 1 % as tau, for the same reason.
EDGE_TOLERANCE_FRACTION = 0.01
# Truth feature edges are sampled every tolerance / 8 for the two tests above, so "within the
# tolerance" is decided to within tolerance / 16.
EDGE_SAMPLES_PER_TOLERANCE = 8
# Points per block in the neighbourhood computations (k * 3 float64 per point, ~100 MB at 2**18).
EDGE_BLOCK = 1 << 17
# Points per nearest-neighbour query of a streamed score (``metrics.score.score_stream``): the
# blocks are gathered into groups this size, each queried once by the truth samples and the
# coverage lattice (completeness and coverage). Each query costs about as much as one into the
# whole cloud, so larger groups are faster; a group holds 24 MB of points at 2**20, and Open3D's
# KD-tree over them about twice that.
STREAM_BLOCK = 1 << 20
# The edge metric of a streamed cloud (``metrics.edges_stream``) finds k-nearest neighbourhoods
# slab by slab, each slab holding at most this many points plus its halo: 24 MB of points and
# about as much again for their KD-tree, as much as the 2**20-point groups above (the k-nearest
# temporaries are bounded by EDGE_BLOCK either way). Fewer points per slab means more passes
# over the input (one per slab, each re-reading it): a 4M-point cloud scored in 2**19-point
# slabs took 7 % more CPU than in 2**20 (8 passes against 4), with the same report.
EDGE_SLAB_POINTS = 1 << 20
# Bins along the truth's longest axis in which the first pass counts the points, to cut slabs
# of at most EDGE_SLAB_POINTS: 4096 bins of a 665 m asteroid are 16 cm wide, and a slab is a run
# of whole bins (a bin holding more than the budget is a slab of its own).
EDGE_STREAM_BINS = 4096
# Halo of a slab, in neighbourhood radii (k-th neighbour distances: the 99th percentile of
# those found so far; for the first slab, that of k points spread uniformly over the truth's
# area). A core point whose neighbourhood reaches past the halo is resolved by a later pass,
# so this sets only how many are: 2 radii leave those within a radius or so of a slab face.
EDGE_HALO_RADII = 2.0
# Exact medians and 95th percentiles of a stream: values in the bins holding the wanted ranks are
# kept and sorted once a bin holds at most this many (8 MB of float64 each); larger bins are
# split by a further pass (metrics.score._RankFinder).
QUANTILE_KEEP = 1 << 20

# --------------------------------------------------------------------------- precision

# What a score states when the caller gives no sample count (``metrics.precision``): the
# Chamfer distance's standard error at most 2 % of it, the F-score's, the coverage's and the
# edge score's at most a quarter of that, 0.005 (half the third decimal). 2 % of a Chamfer
# distance is far below the differences the comparisons rank (methods differ by tens of per
# cent; ``recon stability`` sizes its cells for the same 2 %). On the demo asteroid's Poisson
# surface the truth-to-surface distances spread 9 times their mean (a few regions the surface
# misses by tens of metres): 1 % would ask ~270,000 truth samples, more than TRUTH_SAMPLES,
# 2 % asks ~68,000; its accuracy side needs no more than the pilot.
PRECISION = 0.02
# Pilot samples per side, from which the spreads are estimated before the counts are sized;
# also the least a score to a precision scores.
PILOT_SAMPLES = 1 << 14
# Rounds of "size from what is scored, score the rest": the second corrects a pilot whose
# spread was underestimated (long tails).
PRECISION_ROUNDS = 3
# Most samples per side a score to a precision takes; beyond it, the achieved standard error is
# reported as it is.
MAX_SAMPLES = 1 << 20
# Most points of a cloud its accuracy is averaged over (the smallest keys): a stream keeps up to
# twice this many as it goes (56 bytes a point with normals: 29 MB), less than a query group of
# STREAM_BLOCK points, so the memory of a streamed score stays flat in the cloud's size.
CLOUD_SAMPLES = 1 << 18
