/* Harness-only plant integrator (not firmware), shared by plant.c, the harness's C around the
 * controller (harness/controller_c.py) and the cffi declarations (read from this file).
 *
 * With u held over a tick, each of `substeps` steps is the exponential Euler-Maruyama step
 *     x+ = Ad x + Bd u + fd + sum_i w_i G_i dZ,      dZ ~ N(0, dt I)  (supplied by the caller)
 * with w = [x; u] (state noise i < n, input noise i >= n), and the running cost accumulates
 * the left-point rule dt * L(x, u). All in double. dZ arrives as standard normal numbers
 * times dz_scale (sqrt(dt)), the product taken here. The diffusion is passed as its nonzeros:
 * entry e adds w[g_index[3e]] * g_value[e] * dZ[g_index[3e+2]] to component g_index[3e+1]. */
typedef struct {
    size_t n, m, mz, substeps;
    double dt;
    double dz_scale;                        /* dZ = dz_scale * (the caller's numbers) */
    const double *Ad, *Bd;                  /* (n, n), (n, m): the step's e^{A dt}, Gamma */
    const double *fd;                       /* (n): the step's drift term, or NULL: none */
    size_t g_count;
    const size_t *g_index;
    const double *g_value;
    const double *Q, *S, *q, *R, *r;        /* the stage's running cost */
    double rho;
    int state_cost;                         /* 0 when Q, S and q are zero */
} harness_plant_t;

/* One path over one tick: x (n) advanced in place, u (m) held, dz (substeps, mz). Returns
 * the running cost over the tick; 0 and x unchanged when n > 64 or m > 32. */
double harness_plant_path(const harness_plant_t *pl, const double *u, const double *dz,
                          double *x);
/* 1 when pl runs the step compiled for the module's problem (plant_spec.py), 0 when it runs
 * the generic one (a module without one, or data that do not fit it): the same bits. */
int harness_plant_compiled(const harness_plant_t *pl);
/* Every path: X (paths, n) in place, U (paths, m) float32 commands, dZ (paths, substeps, mz),
 * cost (paths) accumulated. */
void harness_plant_tick(const harness_plant_t *pl, size_t paths, const double *dZ,
                        const float *U, double *X, double *cost);

/* The loop's faults for harness_tick_faults (problem.faults.Faults): a NULL vector is no such
 * fault. Per tick the caller supplies standard normal numbers for the sensor (paths, n) and
 * the actuator (paths, m) and uniform numbers in [0, 1) for missed ticks (paths), and keeps
 * each path's actuator command (`held`, paths x m, starting at the safe command u_hold)
 * across ticks. */
typedef struct {
    const double *sensor_std;     /* (n): measured x = x + sensor_std * N(0, 1) */
    const double *quantum;        /* (n): then rounded to a multiple (0: not rounded) */
    const double *actuator_std;   /* (m): applied u = held + actuator_std * N(0, 1) */
    double miss_probability;      /* the controller is not run when uniform < this */
    int delay_ticks;              /* 1: a command computed at tick j is applied from j + 1 */
    int feed_held;                /* 1 (a table designed for the delay, with delay_ticks 1):
                                     the controller measures [x; held], held the command
                                     applied over this tick (its previous output) */
} harness_faults_t;

/* A corridor the harness watches (problem.corridors.Corridor; harness_tick_watch): the output
 * y = C x after each tick j (the state x(t0 + (j + 1) h)) is checked when first <= j + 1 <=
 * last, for each path that has not left yet; outside the union of the polygons {A_k y <= b_k}
 * (every polygon has a row with a y > b) the path records the tick and the wall: in each
 * polygon its most violated row by a y - b (rows scaled to |a| = 1 by the caller, so this is
 * the distance), of the polygon where that is least (ties: the first). */
typedef struct {
    uint32_t first, last;         /* state ticks checked, both included */
    size_t p, n_poly;             /* outputs (at most 32), polygons */
    const double *C;              /* (p, n) */
    const size_t *row_start;      /* (n_poly + 1): polygon k's walls are row_start[k] ... */
    const double *A, *b;          /* (walls, p), (walls): the rows scaled to unit length */
    int32_t *exit_tick;           /* (paths): first state tick outside, -1: none yet */
    int32_t *exit_wall;           /* (paths): the wall it is attributed to */
} harness_corridor_t;

/* Standard normal numbers (normals.c): xoshiro256++ words through a 256-layer ziggurat,
 * `count` of them into `out`; `state` (4 words, not all zero) is the generator's and
 * advances. About 2 ns a number where numpy's C library takes 7.5-9.5
 * (tools/bench/normal_generators.py); seeded from numpy.random.SeedSequence. */
void harness_normals(uint64_t *state, double *out, size_t count);
