// Real sequential ray trace through a lens prescription: one work-item per ray.
// The OpenCL twin of clpost/optics/trace.py::trace_table (same formulas, double precision,
// same status codes); tests require equal results. Structural: LENS_TRACE_NSURF (surfaces).
// Surface table rows (5 doubles): vertex z, curvature c, semi-diameter, index after, is-stop.
#pragma OPENCL EXTENSION cl_khr_fp64 : enable

#define LT_OK 0
#define LT_MISS 1
#define LT_CLIPPED 2
#define LT_STOP 3
#define LT_TIR 4

__kernel void lens_trace(__constant double *table, __global const double *ray_in,
                         __global double *ray_out, __global char *status,
                         __global short *where, const double z_film, const int n_rays)
{
    const int i = get_global_id(0);
    if (i >= n_rays) return;
    double3 o = (double3)(ray_in[6 * i], ray_in[6 * i + 1], ray_in[6 * i + 2]);
    double3 d = (double3)(ray_in[6 * i + 3], ray_in[6 * i + 4], ray_in[6 * i + 5]);
    d = d / sqrt(dot(d, d));
    double n_prev = 1.0;
    char st = LT_OK;
    short at = -1;
    double sx = 0.0, sy = 0.0;
    for (int k = 0; k < LENS_TRACE_NSURF; ++k) {
        const double zk = table[5 * k], c = table[5 * k + 1], sd = table[5 * k + 2];
        const double n_next = table[5 * k + 3];
        const int is_stop = table[5 * k + 4] != 0.0;
        const double3 p = o - (double3)(0.0, 0.0, zk);
        const double b = c * dot(p, d) - d.z;
        const double cc = c * dot(p, p) - 2.0 * p.z;
        const double disc = b * b - c * cc;
        const double sq = sqrt(fmax(disc, 0.0));
        // Vertex-side root in the form without cancellation (see trace.py).
        const double t = (-b > 0.0) ? cc / (-b + sq) : (-b - sq) / c;
        if (disc < 0.0 || !isfinite(t)) { st = LT_MISS; at = k; break; }
        const double3 q = p + t * d;
        if (is_stop) { sx = q.x; sy = q.y; }  // recorded for blocked rays too (pupil maps)
        if (q.x * q.x + q.y * q.y > sd * sd) { st = is_stop ? LT_STOP : LT_CLIPPED; at = k; break; }
        const double3 new_o = q + (double3)(0.0, 0.0, zk);
        double3 new_d = d;
        if (n_next != n_prev || c != 0.0) {
            double3 nrm = (double3)(c * q.x, c * q.y, c * q.z - 1.0);
            nrm = nrm / sqrt(dot(nrm, nrm));
            const double mu = n_prev / n_next;
            const double cosi = -dot(d, nrm);
            const double kk = 1.0 - mu * mu * (1.0 - cosi * cosi);
            if (kk < 0.0) { st = LT_TIR; at = k; break; }
            new_d = mu * d + (mu * cosi - sqrt(kk)) * nrm;
        }
        o = new_o;
        d = new_d;
        n_prev = n_next;
    }
    if (st == LT_OK) {
        if (!(d.z > 0.0)) { st = LT_MISS; at = LENS_TRACE_NSURF; }
        else o = o + ((z_film - o.z) / d.z) * d;
    }
    ray_out[8 * i] = o.x; ray_out[8 * i + 1] = o.y; ray_out[8 * i + 2] = o.z;
    ray_out[8 * i + 3] = d.x; ray_out[8 * i + 4] = d.y; ray_out[8 * i + 5] = d.z;
    ray_out[8 * i + 6] = sx; ray_out[8 * i + 7] = sy;
    status[i] = st;
    where[i] = at;
}
