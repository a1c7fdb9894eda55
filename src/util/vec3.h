/* The one vec3 set: double[3] helpers, (inputs..., output) argument order;
 * an output may alias an input. Each is the plain expression (no FMA, same
 * order as the code it replaced), so results stay bit for bit. */
#ifndef VX_VEC3_H
#define VX_VEC3_H

#include <math.h>

/* o = a + b */
static inline void vx_v3_add(const double *a, const double *b, double *o)
{
    for (int c = 0; c < 3; c++)
        o[c] = a[c] + b[c];
}

/* o = a - b */
static inline void vx_v3_sub(const double *a, const double *b, double *o)
{
    for (int c = 0; c < 3; c++)
        o[c] = a[c] - b[c];
}

/* o = s a */
static inline void vx_v3_scale(const double *a, double s, double *o)
{
    for (int c = 0; c < 3; c++)
        o[c] = s * a[c];
}

/* o = (a + b) / 2, as 0.5 * (a + b) */
static inline void vx_v3_mid(const double *a, const double *b, double *o)
{
    for (int c = 0; c < 3; c++)
        o[c] = 0.5 * (a[c] + b[c]);
}

/* a . b */
static inline double vx_v3_dot(const double *a, const double *b)
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* o = a x b; o must not alias a or b. */
static inline void vx_v3_cross(const double *a, const double *b, double *o)
{
    o[0] = a[1] * b[2] - a[2] * b[1];
    o[1] = a[2] * b[0] - a[0] * b[2];
    o[2] = a[0] * b[1] - a[1] * b[0];
}

/* |a| */
static inline double vx_v3_norm(const double *a)
{
    return sqrt(vx_v3_dot(a, a));
}

/* Scales a to unit length in place: 0, or -1 (a unchanged) when its length
 * is 0 or not a number. */
static inline int vx_v3_unit(double *a)
{
    double l = vx_v3_norm(a);
    if (!(l > 0)) return -1;
    for (int c = 0; c < 3; c++)
        a[c] /= l;
    return 0;
}

#endif
