"""The quadratic B-spline stencil that ties a particle to its 27 grid nodes (its weights and their
gradients, for the adjoints; the nodes' offsets per axis, and the per-axis rows of a matrix times
them, for the adjoints' loops), reading and writing a particle's state row (layout.STATE)
inside kernels, and how the serial scatters are spread over two threads (``scatter_spread``)."""
import taichi as ti


@ti.func
def row_at(slot, e, p, B, N, width: ti.template()):
    """First index of particle p's row of env e in slot (a frame or substep) of a per-particle
    array (slots, B, N, width) passed flat. The kernels take the particle rows (frames, affine,
    svd, gathered, grads, scratch) flat: an index into a flat array costs one load of its
    pointer, where a 4-d ndarray reloads its shape after every store and multiplies it out per
    access. Indices are 32-bit (solver.MAX_ARRAY_ELEMENTS bounds the arrays)."""
    return ((slot * B + e) * N + p) * width


@ti.func
def row_matrix(rows: ti.template(), at):
    """The 3×3 matrix stored row-major at rows[at..at + 8] (a flat per-particle array)."""
    m = ti.Matrix.zero(float, 3, 3)
    for i in ti.static(range(3)):
        for j in ti.static(range(3)):
            m[i, j] = rows[at + 3 * i + j]
    return m


@ti.func
def row_vector(rows: ti.template(), at):
    """The 3-vector at rows[at..at + 2]."""
    return ti.Vector([rows[at], rows[at + 1], rows[at + 2]])


@ti.func
def store_matrix(rows: ti.template(), at, m):
    for i in ti.static(range(3)):
        for j in ti.static(range(3)):
            rows[at + 3 * i + j] = m[i, j]


@ti.func
def store_vector(rows: ti.template(), at, v):
    for i in ti.static(range(3)):
        rows[at + i] = v[i]


@ti.func
def bspline(fx, i):
    """Quadratic B-spline weight (3,) of node offset i ∈ {0, 1, 2} for a particle at fx (3,)
    cells from its base node (fx ∈ [0.5, 1.5) per axis)."""
    return ti.select(i == 0, 0.5 * (1.5 - fx) ** 2, ti.select(i == 1, 0.75 - (fx - 1.0) ** 2, 0.5 * (fx - 0.5) ** 2))


@ti.func
def bspline_grad(fx, i):
    """d bspline(fx, i) / d fx, per axis (3,)."""
    return ti.select(i == 0, fx - 1.5, ti.select(i == 1, -2.0 * (fx - 1.0), fx - 0.5))


@ti.func
def weights(fx):
    """3×3: row i holds the three axes' B-spline weights of node offset i (node (i, j, k)'s weight
    is W[i, 0] · W[j, 1] · W[k, 2]). Computed once per particle: evaluating the B-splines per node
    made the stencil loops 3× slower."""
    return ti.Matrix.rows([bspline(fx, 0), bspline(fx, 1), bspline(fx, 2)])


@ti.func
def weight_grads(fx):
    """3×3: row i holds d bspline(fx, i) / d fx per axis (1/cell)."""
    return ti.Matrix.rows([bspline_grad(fx, 0), bspline_grad(fx, 1), bspline_grad(fx, 2)])


@ti.func
def node_count(grid_i: ti.template()):
    """K, the grid's nodes per env. The grid arrays are passed to the kernels flat, (B · K · 4,):
    node n of env e holds its 4 values at node_at(e, n, K) + 0..3. Indexing a flat array costs
    one load of its pointer where a (B, K, 4) one reloads its shape after every store (a substep of
    10k particles, float32: 1.59 → 1.48 ms, the same bits)."""
    return grid_i[3] * grid_i[4] * grid_i[5]


@ti.func
def node_at(e, n, K):
    """First index of node n of env e in a flat grid array (node_count)."""
    return 4 * (e * K + n)


@ti.func
def node_vector(grid: ti.template(), at):
    """The node's first three values (momentum, velocity or their gradient) from index at, as a 3-vector."""
    return ti.Vector([grid[at], grid[at + 1], grid[at + 2]])


@ti.func
def stencil_row(grid_i: ti.template(), base, i, j):
    """Flat index of node (i, j, 0) of the stencil at ``base`` (node (i, j, k) is this + k). Callers
    loop i, j, k as three runtime loops: one loop over 27 decoding o // 9, o // 3 % 3, o % 3 ran
    1.7× slower."""
    return ((base[0] + i) * grid_i[4] + base[1] + j) * grid_i[5] + base[2]


@ti.func
def axis_offsets(fx):
    """3×3: [a, c] = a − fx[c], the offset (cells) of the stencil's nodes a ∈ {0, 1, 2} along
    axis c from a particle at fx (node (i, j, k)'s offset − fx is (O[i, 0], O[j, 1], O[k, 2]))."""
    return ti.Matrix([[float(a) - fx[c] for c in ti.static(range(3))] for a in ti.static(range(3))])


@ti.func
def column_terms(M, D, c: ti.template()):
    """3×3: row a holds column c of M (3×3) times D[a, c]: with D[a, c] node a's offset along axis
    c (axis_offsets, in cells or metres), M @ offset at node (i, j, k) is row i of column_terms(M,
    D, 0) + row j of (…, 1) + row k of (…, 2), summed in a matrix product's order, so the stencil
    loops add three precomputed rows instead of taking a product per node."""
    return ti.Matrix([[M[r, c] * D[a, c] for r in ti.static(range(3))] for a in ti.static(range(3))])


@ti.func
def matrix_row(M, a):
    """Row a (a runtime index) of a 3×3 matrix, as a 3-vector."""
    return ti.Vector([M[a, 0], M[a, 1], M[a, 2]])


@ti.func
def transposed_times(M, v):
    """Mᵀ v (3,) for a 3×3 M, summed in a matrix product's order (less its zero start)."""
    return ti.Vector([M[0, c] * v[0] + M[1, c] * v[1] + M[2, c] * v[2] for c in ti.static(range(3))])


@ti.func
def cell_of(pos, inv_dx, grid_i: ti.template()):
    """(base node (3, int, relative to the grid's lowest node), fx (3,) cells) of a particle at
    pos (3,) m. The base is clamped into the grid so that no index can leave it, even for a
    non-finite position (flagged elsewhere)."""
    scaled = pos * inv_dx
    base = ti.floor(scaled - 0.5, int)
    fx = scaled - base
    lowest = ti.Vector([grid_i[0], grid_i[1], grid_i[2]])
    top = ti.Vector([grid_i[3] - 3, grid_i[4] - 3, grid_i[5] - 3])
    return ti.max(ti.min(base - lowest, top), 0), fx


@ti.func
def scatter_spread(B):
    """The serial scatters (p2g's, and g2p's reverse) run each env's particles in two halves by index
    (the first ``(N + 1) // 2``, the rest), each serially in particle order into its own grid, which
    are then added (node by node, first + second): the same sums whatever the machine or the number
    of envs. The 2·B half-scatters are iterations t of a loop of 2·B·spread where t % spread == 0
    (half t // spread % 2 of env t // spread // 2): Taichi's CPU backend runs a parallel loop of few
    iterations on one thread (measured: 2, 4 or 64 long iterations took as long as run one after
    another; 2 long ones spread over 2048 ran on two threads, 45 ms against 85)."""
    return ti.max(1, 1024 // B)


@ti.func
def scatter_half(t, B, N):
    """Iteration t of a two-half scatter's loop, range(2 * B * scatter_spread(B)): (working: 1 for the
    iterations that run a half, 0 for the spread's idle ones; its env e; second: 0 for the first
    half, 1 for the second; its particles first..end − 1)."""
    spread = scatter_spread(B)
    half = (N + 1) // 2
    e, second = t // spread // 2, t // spread % 2
    return int(t % spread == 0), e, second, ti.select(second == 0, 0, half), ti.select(second == 0, half, N)
