// Reference basis functions (VTK vertex order) and inverse element maps.
// P1 on simplices is barycentric; Q1 on quadrilaterals and hexahedra is
// (bi/tri)linear on [0,1]^d.
#pragma once

#include "common.hpp"

namespace vc {

inline void q1_quad(double x, double y, double* phi) {
  phi[0] = (1 - x) * (1 - y);
  phi[1] = x * (1 - y);
  phi[2] = x * y;
  phi[3] = (1 - x) * y;
}

inline void q1_quad_grad(double x, double y, double* dx, double* dy) {
  dx[0] = -(1 - y); dx[1] = (1 - y); dx[2] = y; dx[3] = -y;
  dy[0] = -(1 - x); dy[1] = -x; dy[2] = x; dy[3] = (1 - x);
}

inline void q1_hex(double x, double y, double z, double* phi) {
  double q[4];
  q1_quad(x, y, q);
  for (int k = 0; k < 4; ++k) {
    phi[k] = q[k] * (1 - z);
    phi[k + 4] = q[k] * z;
  }
}

inline void q1_hex_grad(double x, double y, double z, double* g /* 8 x 3 */) {
  double q[4], dx[4], dy[4];
  q1_quad(x, y, q);
  q1_quad_grad(x, y, dx, dy);
  for (int k = 0; k < 4; ++k) {
    g[3 * k + 0] = dx[k] * (1 - z); g[3 * k + 1] = dy[k] * (1 - z); g[3 * k + 2] = -q[k];
    g[3 * (k + 4) + 0] = dx[k] * z; g[3 * (k + 4) + 1] = dy[k] * z; g[3 * (k + 4) + 2] = q[k];
  }
}

inline bool solve3(const double A[3][3], const double b[3], double x[3]) {
  const double det = A[0][0] * (A[1][1] * A[2][2] - A[1][2] * A[2][1]) -
                     A[0][1] * (A[1][0] * A[2][2] - A[1][2] * A[2][0]) +
                     A[0][2] * (A[1][0] * A[2][1] - A[1][1] * A[2][0]);
  if (det == 0.0) return false;
  for (int c = 0; c < 3; ++c) {
    double M[3][3];
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) M[i][j] = (j == c) ? b[i] : A[i][j];
    x[c] = (M[0][0] * (M[1][1] * M[2][2] - M[1][2] * M[2][1]) -
            M[0][1] * (M[1][0] * M[2][2] - M[1][2] * M[2][0]) +
            M[0][2] * (M[1][0] * M[2][1] - M[1][1] * M[2][0])) / det;
  }
  return true;
}

// Reference coordinates of x in a trilinear hexahedron (Newton; converges in a
// few steps for the mildly distorted hexes of meshes; exact for parallelepipeds
// after one step).
inline Vec3 invert_hex(const Vec3* v, const Vec3& x) {
  double xi[3] = {0.5, 0.5, 0.5};
  for (int it = 0; it < 30; ++it) {
    double phi[8], g[24];
    q1_hex(xi[0], xi[1], xi[2], phi);
    q1_hex_grad(xi[0], xi[1], xi[2], g);
    double r[3] = {-x[0], -x[1], -x[2]};
    double J[3][3] = {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}};
    for (int k = 0; k < 8; ++k)
      for (int d = 0; d < 3; ++d) {
        r[d] += phi[k] * v[k][d];
        for (int e = 0; e < 3; ++e) J[d][e] += v[k][d] * g[3 * k + e];
      }
    double dxi[3];
    if (!solve3(J, r, dxi)) break;
    double step = 0.0;
    for (int d = 0; d < 3; ++d) {
      xi[d] -= dxi[d];
      step = std::max(step, std::fabs(dxi[d]));
    }
    if (step < 1e-15) break;
  }
  return {xi[0], xi[1], xi[2]};
}

}  // namespace vc
