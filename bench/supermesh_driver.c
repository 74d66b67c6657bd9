/* P1-P1 coupling matrix B between two tet meshes with libsupermesh (comparison
 * point for bench/transfer.py; compiled on demand against the PyPI package
 * `libsupermesh`, which ships only the shared library and its C header).
 *
 * B[k, i] = int lambda_i^source lambda_k^target over the supermesh: libsupermesh's
 * R-tree intersection finder gives the candidate pairs, libsupermesh_intersect_tets_real
 * clips each pair into tets, and each piece is integrated exactly (the product of two
 * affine functions on a tet: |c|/20 (sum_v f_v g_v + sum_v f_v sum_v g_v)).
 * The element contributions are written as COO triplets; the caller sums them into CSR.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define TET_BUF_SIZE 81

void libsupermesh_tree_intersection_finder_set_input(long*, int*, long*, int*, long*, int*, long*, int*,
                                                     double*, long*, double*, long*);
void libsupermesh_tree_intersection_finder_query_output(long*);
void libsupermesh_tree_intersection_finder_get_output(long*, long*, long*, long*);
void libsupermesh_intersect_tets_real(double*, double*, double*, int*);

static int* g_rows = NULL;
static int* g_cols = NULL;
static double* g_vals = NULL;
static long g_n = 0, g_cap = 0;

static double now(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

/* per tet: inverse Jacobian (9, row-major) and first vertex (3) */
static void affine_inverses(const double* pts, const long* cells, long n, double* out) {
  for (long c = 0; c < n; ++c) {
    const double* p0 = pts + 3 * cells[4 * c];
    double J[3][3];
    for (int j = 0; j < 3; ++j) {
      const double* pj = pts + 3 * cells[4 * c + j + 1];
      for (int d = 0; d < 3; ++d) J[d][j] = pj[d] - p0[d];
    }
    double det = J[0][0] * (J[1][1] * J[2][2] - J[1][2] * J[2][1]) -
                 J[0][1] * (J[1][0] * J[2][2] - J[1][2] * J[2][0]) +
                 J[0][2] * (J[1][0] * J[2][1] - J[1][1] * J[2][0]);
    double* m = out + 12 * c;
    m[0] = (J[1][1] * J[2][2] - J[1][2] * J[2][1]) / det;
    m[1] = (J[0][2] * J[2][1] - J[0][1] * J[2][2]) / det;
    m[2] = (J[0][1] * J[1][2] - J[0][2] * J[1][1]) / det;
    m[3] = (J[1][2] * J[2][0] - J[1][0] * J[2][2]) / det;
    m[4] = (J[0][0] * J[2][2] - J[0][2] * J[2][0]) / det;
    m[5] = (J[0][2] * J[1][0] - J[0][0] * J[1][2]) / det;
    m[6] = (J[1][0] * J[2][1] - J[1][1] * J[2][0]) / det;
    m[7] = (J[0][1] * J[2][0] - J[0][0] * J[2][1]) / det;
    m[8] = (J[0][0] * J[1][1] - J[0][1] * J[1][0]) / det;
    m[9] = p0[0];
    m[10] = p0[1];
    m[11] = p0[2];
  }
}

static void barycentric(const double* m, const double* x, double* lam) {
  double r[3] = {x[0] - m[9], x[1] - m[10], x[2] - m[11]};
  double a = m[0] * r[0] + m[1] * r[1] + m[2] * r[2];
  double b = m[3] * r[0] + m[4] * r[1] + m[5] * r[2];
  double c = m[6] * r[0] + m[7] * r[1] + m[8] * r[2];
  lam[0] = 1.0 - a - b - c;
  lam[1] = a;
  lam[2] = b;
  lam[3] = c;
}

static double tet_volume(const double* t) {
  double a[3], b[3], c[3];
  for (int d = 0; d < 3; ++d) {
    a[d] = t[3 + d] - t[d];
    b[d] = t[6 + d] - t[d];
    c[d] = t[9 + d] - t[d];
  }
  return fabs(a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
              a[2] * (b[0] * c[1] - b[1] * c[0])) / 6.0;
}

static int push(int r, int c, double v) {
  if (g_n == g_cap) {
    long cap = g_cap ? 2 * g_cap : (1L << 20);
    int* rows = realloc(g_rows, cap * sizeof(int));
    int* cols = realloc(g_cols, cap * sizeof(int));
    double* vals = realloc(g_vals, cap * sizeof(double));
    if (!rows || !cols || !vals) return -1;
    g_rows = rows, g_cols = cols, g_vals = vals, g_cap = cap;
  }
  g_rows[g_n] = r, g_cols[g_n] = c, g_vals[g_n] = v, ++g_n;
  return 0;
}

/* Returns the number of COO entries (fetch them with lsm_fetch), -1 on allocation failure.
 * times: [search seconds, intersect + integrate seconds]; counts: [pairs tested, pairs intersected]. */
long lsm_p1p1(long nsp, double* spts, long nsc, long* scells, long ntp, double* tpts, long ntc, long* tcells,
              double* times, long* counts) {
  int dim = 3, loc = 4;
  g_n = 0;
  double t0 = now();
  /* mesh a = target, mesh b = source: for each target tet, the candidate source tets */
  libsupermesh_tree_intersection_finder_set_input(&ntp, &dim, &ntc, &loc, &nsp, &dim, &nsc, &loc, tpts, tcells,
                                                  spts, scells);
  long nind = 0;
  libsupermesh_tree_intersection_finder_query_output(&nind);
  long* ind = malloc((nind > 0 ? nind : 1) * sizeof(long));
  long* ptr = malloc((ntc + 1) * sizeof(long));
  libsupermesh_tree_intersection_finder_get_output(&ntc, &nind, ind, ptr);
  double t1 = now();

  double* sinv = malloc(12 * nsc * sizeof(double));
  double* tinv = malloc(12 * ntc * sizeof(double));
  affine_inverses(spts, scells, nsc, sinv);
  affine_inverses(tpts, tcells, ntc, tinv);
  double ta[12], tb[12], pieces[12 * TET_BUF_SIZE];
  long intersected = 0;
  int failed = 0;
  for (long t = 0; t < ntc && !failed; ++t) {
    for (int v = 0; v < 4; ++v) memcpy(ta + 3 * v, tpts + 3 * tcells[4 * t + v], 3 * sizeof(double));
    for (long q = ptr[t]; q < ptr[t + 1]; ++q) {
      long s = ind[q];
      for (int v = 0; v < 4; ++v) memcpy(tb + 3 * v, spts + 3 * scells[4 * s + v], 3 * sizeof(double));
      int npieces = 0;
      libsupermesh_intersect_tets_real(ta, tb, pieces, &npieces);
      if (npieces == 0) continue;
      double local[4][4] = {{0}};
      double total = 0.0;
      for (int p = 0; p < npieces; ++p) {
        const double* c = pieces + 12 * p;
        double vol = tet_volume(c);
        if (vol <= 0.0) continue;
        total += vol;
        double ls[4][4], lt[4][4], ss[4] = {0}, st[4] = {0};
        for (int v = 0; v < 4; ++v) {
          barycentric(sinv + 12 * s, c + 3 * v, ls[v]);
          barycentric(tinv + 12 * t, c + 3 * v, lt[v]);
          for (int i = 0; i < 4; ++i) ss[i] += ls[v][i], st[i] += lt[v][i];
        }
        double w = vol / 20.0;
        for (int k = 0; k < 4; ++k)
          for (int i = 0; i < 4; ++i) {
            double sum = st[k] * ss[i];
            for (int v = 0; v < 4; ++v) sum += lt[v][k] * ls[v][i];
            local[k][i] += w * sum;
          }
      }
      if (total <= 0.0) continue;
      ++intersected;
      for (int k = 0; k < 4 && !failed; ++k)
        for (int i = 0; i < 4; ++i)
          if (push((int)tcells[4 * t + k], (int)scells[4 * s + i], local[k][i])) {
            failed = 1;
            break;
          }
    }
  }
  double t2 = now();
  times[0] = t1 - t0;
  times[1] = t2 - t1;
  counts[0] = nind;
  counts[1] = intersected;
  free(ind), free(ptr), free(sinv), free(tinv);
  return failed ? -1 : g_n;
}

void lsm_fetch(int* rows, int* cols, double* vals) {
  memcpy(rows, g_rows, g_n * sizeof(int));
  memcpy(cols, g_cols, g_n * sizeof(int));
  memcpy(vals, g_vals, g_n * sizeof(double));
  free(g_rows), free(g_cols), free(g_vals);
  g_rows = NULL, g_cols = NULL, g_vals = NULL, g_n = 0, g_cap = 0;
}
