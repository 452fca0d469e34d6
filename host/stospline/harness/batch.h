/* Harness-only loops over controller instances (controller_c.py's BATCH), declared for the
 * module that wraps them (its cffi declarations are read from this file) and for the loops'
 * own translation unit, which is compiled once per build and linked into every module of
 * that build. Include after stospline/stsp_controller.h and plant.h. */
int harness_run_ticks(stsp_ctrl_t *ctrls, size_t count, uint32_t j0, uint32_t j1,
                      const harness_plant_t *pl, uint64_t *rng, double *dZ, double *X,
                      double *cost, int64_t *saturated, double *u_low, double *u_high,
                      double *x_sum, float *u_rec, size_t n_rec,
                      const harness_corridor_t *cor, size_t n_cor, double *sample_x,
                      double *sample_u, float *rec_x, float *rec_u, size_t n_keep);
int harness_init_batch(stsp_ctrl_t *ctrls, size_t count, const stsp_table_t *table);
int harness_corridor_compiled(const harness_corridor_t *c, size_t k, size_t n);
int harness_step_batch(stsp_ctrl_t *ctrls, size_t count, uint32_t tick,
                       const stsp_scalar_t *x, stsp_scalar_t *u, int *status);
int harness_pair_batch(const stsp_ctrl_t *proto, size_t count, const uint32_t *t_latch,
                       const stsp_scalar_t *x_latch, const uint32_t *tick,
                       const stsp_scalar_t *x, stsp_scalar_t *u, int *status);
int harness_tick(stsp_ctrl_t *ctrls, size_t count, uint32_t tick, const harness_plant_t *pl,
                 const double *dZ, double *X, double *cost, int64_t *saturated,
                 double *u_low, double *u_high, double *x_sum, float *u_rec, size_t n_rec);
int harness_tick_faults(stsp_ctrl_t *ctrls, size_t count, uint32_t tick,
                        const harness_plant_t *pl, const double *dZ, double *X, double *cost,
                        int64_t *saturated, double *u_low, double *u_high, double *x_sum,
                        float *u_rec, size_t n_rec, const harness_faults_t *f,
                        const double *sensor_z, const double *actuator_z, const double *miss_u,
                        double *held);
int harness_tick_watch(stsp_ctrl_t *ctrls, size_t count, uint32_t tick,
                       const harness_plant_t *pl, const double *dZ, double *X, double *cost,
                       int64_t *saturated, double *u_low, double *u_high, double *x_sum,
                       float *u_rec, size_t n_rec, const harness_faults_t *f,
                       const double *sensor_z, const double *actuator_z, const double *miss_u,
                       double *held, const harness_corridor_t *cor, size_t n_cor);