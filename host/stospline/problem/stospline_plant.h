/* stospline_plant.h: the interface of a plant model in C ([plant] source = "model.c").
 *
 * The model is the Ito SDE  dX = f(t, X, u, p) dt + g(t, X, u, p) dZ  with X in R^n, u in R^m,
 * Z in R^mz a standard Brownian motion and p the problem file's [plant] params. A model file
 * defines the three functions below (it may #include this header; stospline compiles it with
 * the header in front either way, so a definition that differs from these prototypes is a
 * compile error that names the function).
 *
 *   stospline_plant_dims  writes dims[0..3] = n, m, mz and the number of parameters it reads;
 *                         the problem's x0 and params must have these lengths.
 *   stospline_plant_drift writes f (n values).
 *   stospline_plant_diffusion writes g, n x mz, row-major: g[i * mz + j] multiplies dZ_j in
 *                         the equation of x_i.
 *
 * The drift and the diffusion return 0 on success; any other value refuses the point (t, x, u)
 * and stops the run with that value in the message. Both must be pure functions of their
 * arguments (no static state): stospline calls them in any order, at perturbed points to
 * differentiate them, and from several threads. Outputs must be finite.
 */
#ifndef STOSPLINE_PLANT_H
#define STOSPLINE_PLANT_H

void stospline_plant_dims(int dims[4]);
int stospline_plant_drift(double t, const double *x, const double *u, const double *p,
                          double *f);
int stospline_plant_diffusion(double t, const double *x, const double *u, const double *p,
                              double *g);

#endif
